"""Reproducible experiments for the TSKF (pure Python, no ROS needed)."""
