"""CLIP / OpenCLIP ViT image embedder plugin for zooctl (see README.md)."""
