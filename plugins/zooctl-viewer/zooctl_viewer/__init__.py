"""zooctl-viewer: `zooctl view`, the fitted character in 3D beside its video, and the bank as a gallery."""
