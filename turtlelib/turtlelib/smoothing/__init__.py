"""Smoothing: a filter's whole run re-estimated at once (the factors, the solver, associations revised)."""
