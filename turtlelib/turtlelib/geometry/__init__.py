"""SE(2) geometry: the pose and twist value types, stamped pose buffers, decimated pose trails."""
