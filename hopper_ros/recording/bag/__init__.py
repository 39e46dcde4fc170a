"""rosbag2 bags as ROS 2 itself writes them with the MCAP storage plugin: a folder holding
`metadata.yaml` and `<folder>_0.mcap` (profile "ros2", messages "cdr", schemas "ros2msg" with
their dependencies as rosbag2 writes them (schemas.py), channels with `offered_qos_profiles`
and `topic_type_hash`, zstd-compressed chunks, message and chunk indexes, statistics, a
summary section and the bag's metadata as the "rosbag2" metadata record).

metadata.yaml is rosbag2's (Kilted, rosbag2_storage metadata version 9): the same keys in the
same order, emitted in yaml-cpp's style (sequences indented under their key, `~` for an empty
custom_data, `""` for empty strings, no newline after the last line), so that it reads as one
`ros2 bag record` wrote (rosbag2_storage/include/rosbag2_storage/yaml.hpp).

Crash safety. Every byte the MCAP writer produces goes straight to the file (no user-space
buffer), and a chunk is closed when it reaches `chunk_size` bytes or `chunk_interval` seconds,
whichever comes first. A recorder killed with SIGKILL therefore leaves complete chunks on
disk and loses at most the chunk it was filling; the file then lacks its summary and footer
and the folder its metadata.yaml. `BagReader` reads such a bag anyway (record by record, up
to the last intact chunk), `bag_info` says it is unfinished, and `recover_bag` rewrites it as
a complete bag (the original MCAP is kept beside it as `*.mcap.unfinished`).
"""

from .metadata import BAG_VERSION, DEFAULT_QOS, ROS_DISTRO, BagError, RawMessage, TopicInfo, dump_yaml_cpp_style, metadata_document
from .reader import MAX_CHUNK_BYTES, MCAP_MAGIC, BagReader, McapScan
from .recovery import BagInfo, Recovery, bag_info, recover_bag
from .writer import DEFAULT_CHUNK_INTERVAL, DEFAULT_CHUNK_SIZE, BagWriter

__all__ = ["BAG_VERSION", "DEFAULT_QOS", "ROS_DISTRO", "BagError", "RawMessage", "TopicInfo", "dump_yaml_cpp_style",
           "metadata_document", "MAX_CHUNK_BYTES", "MCAP_MAGIC", "BagReader", "McapScan", "BagInfo", "Recovery",
           "bag_info", "recover_bag", "DEFAULT_CHUNK_INTERVAL", "DEFAULT_CHUNK_SIZE", "BagWriter"]
