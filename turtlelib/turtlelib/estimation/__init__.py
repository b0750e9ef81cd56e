"""Estimation: the EKF (state, tracks, measurement models, association, linearisation), the timeline that
feeds it in time order with what acts on each scan (the update, slip recovery), and the run it records."""
