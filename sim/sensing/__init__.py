"""The cameras' sensor: the synthetic 2D pose detector, in its parts: `profiles` (the error model's
parameters), `rays` (occlusion), `draws` (the random errors) and `detector` (the `Detector` that runs them)."""
