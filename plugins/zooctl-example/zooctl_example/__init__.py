"""Example zooctl plugin package."""
