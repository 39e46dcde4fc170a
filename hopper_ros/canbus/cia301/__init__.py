"""CiA 301 (CANopen) pieces of our own on python-can frames, for any device, both sides. No ROS.

- `master`      the master's (client's) primitives: NMT, `SdoClient` (`SdoError`: the server aborted),
                `PdoMapping`, SYNC, heartbeat consumer, EMCY decoding (the motor driver uses them)
- `sdo_server`  a device's SDO server: expedited and segmented upload and download, CiA 301 aborts
                (`SdoRefused`: what the device's dictionary refuses, with its abort code)
- `pdo`         a device's PDO engine: 4 RPDOs and 4 TPDOs, remapping by SDO, SYNC consumer,
                event-driven and RTR TPDOs
- `values`      dictionary values <-> bytes by CiA 301 data type
- `counters`    what a device counts of its CiA 301 traffic
The protocol numbers live in hopper_ros/canbus/epos2_objects.py; the EPOS2 (CiA 402, NMT, EMCY,
heartbeat, its dictionary's rules) in hopper_ros/canbus/epos2_emulator.py.
"""
