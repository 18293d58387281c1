"""Planners: sensor-design search (design/) and capture planning (capture/)."""
