"""The evaluation of a SLAM run, without ROS: numpy, scipy, matplotlib and turtlelib only.

Modules: ``metrics`` (accuracy and consistency metrics), ``plots`` (figures, matplotlib imported lazily),
``run_evaluation`` (what a demo run and a bag replay both write: metrics.json and the figures),
``datasets`` (readers of the real MRCLAM and Victoria Park datasets, the experiments on them and the noise
calibration: ``python -m nuturtle_eval.datasets``). See docs/demo.md and docs/real_data.md.
"""
