"""The simulated robot: the extended TD-SLIP physics with switchable extra effects, the boom
encoders, the hip motor behind an emulated EPOS2, the microcontroller's packet stream and a
force plate. No ROS import; the sim_robot node is a thin adapter over `robot.SimRobot`."""
