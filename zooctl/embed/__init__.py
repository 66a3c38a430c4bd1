"""Image embedders for video-to-template retrieval (see `zooctl.embed.base` for the interface)."""
