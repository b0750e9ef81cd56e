"""Sensing: the 2D LiDAR scan model (simulation), landmark detection in a scan, circle fits."""
