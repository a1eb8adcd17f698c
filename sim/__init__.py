"""The testbed's world and sensors: store, people, cameras, clocks and the synthetic 2D detector."""
