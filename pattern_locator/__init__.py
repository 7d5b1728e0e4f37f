"""Robot self-location from colour-dot cards and one camera (ROS-free core)."""

__version__ = '0.1.0'
