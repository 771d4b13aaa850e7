"""veg_area_ros: projected frontal area of aquatic plants from calibrated underwater images."""

__version__ = "0.1.0"
