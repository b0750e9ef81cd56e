"""Readers and the runner for real datasets: ``mrclam`` reads one robot of a UTIAS MRCLAM dataset, and
``victoria`` reads the Victoria Park run (dead reckoning, tree detections and GPS on the common time
base). Pure numpy/scipy, no ROS. Every time is int64 nanoseconds, every length metres and every angle
radians.
"""
