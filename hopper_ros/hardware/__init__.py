"""The robot's hardware as data: boom and encoder kinematics (appendix A), the hip motor's
conversions, and the microcontroller's UDP packet. Shared by the simulated robot and the
nodes that talk to the real one, so both sides agree by construction. No ROS import."""
