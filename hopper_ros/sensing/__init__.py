"""The sensing half of the 1 kHz loop as plain Python (no ROS): the encoder bridge (packets to
checked, converted samples), the state estimator (appendix A's Kalman filters) and the event
detector (apex, pre-touchdown, touchdown, bottom, lift-off). The nodes encoder_bridge,
state_estimator and event_detector are thin adapters over `bridge`, `estimator` and `events`.
Settings: config/sensing.yaml (`config.load_sensing_config`). Description: docs/sensing.md."""
