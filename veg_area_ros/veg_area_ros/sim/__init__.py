"""Synthetic ground truth: the simulated cameras and scenes, the calibration demo and the paper's experiment
reproduced. The only home of the synthetic set-up's constants. No ROS here."""
