"""What every part of the project shares: skeletons, cameras and frames, the compile switch, the error base.

`sim/`, `tracker/` and the glue (`crossview/`) import from here; this package imports none of them.
"""
