"""Pictures: top-down layouts and coverage maps (OpenCV), and what the cameras saw, rendered by MuJoCo with
detections and tracks drawn over it."""
