"""Reports: markdown tables and PNG plots written into a folder. No ROS import."""
