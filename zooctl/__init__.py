"""zooctl: rigged 3D characters from casual animal videos (CASA) and generated motions (Ponymation)."""

__version__ = "0.1.0"
