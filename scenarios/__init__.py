"""The scenario files shipped with the project (`*.toml`), installed with it as package data.

`sim.scenario` finds them here by name (`crossview run store_layout2`); the package holds no code.
"""
