"""Data in: recording types, readers and writers per format, alignment of ground truth onto IMU
stamps, dataset discovery, splits, and the label cache that training reads. No torch."""
