"""File formats: glTF import, USD and glTF export, video files."""
