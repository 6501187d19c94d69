"""The torque side: measured torque sets, the candidate effects' torque columns and the scale check."""
