"""Control: the deadbeat controller of chapter 5 and the experiment state machines (no ROS)."""
