"""Measuring what the simulation stands for: a detector's error statistics (against real detections or a recording),
fitting a profile to them, and the cameras' coverage of a floor."""
