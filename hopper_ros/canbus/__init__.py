"""CAN bus side of the hip drive: maxon EPOS2 constants (`epos2_objects`), an emulated EPOS2
(`epos2_emulator`, its position regulator in `epos2_regulator`) built on the generic CiA 301 pieces
of `cia301` (SDO server, PDO engine; the master's primitives there too), the motor driver (`driver`),
and a loopback-only socketcand hub (`socketcand_server`, its protocol text in `socketcand_protocol`) that lets other processes reach an
in-process python-can bus. No ROS.
"""
