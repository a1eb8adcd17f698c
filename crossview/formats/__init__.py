"""Other projects' file formats: the dataset layout (Campus, Shelf, Panoptic), OpenPose/MMPose JSON detections,
tracker result files, and the strict JSON reading they share."""
