"""Mapping: the occupancy grid and its map_server files, the landmark map file, atomic file writes."""
