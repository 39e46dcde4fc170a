"""The start both CANopen master scripts share (python-can's socketcand client and the independent
`canopen` library, no hopper_ros): the drive named on the command line, on the loopback hub."""

import canopen


def connect(argv, sdo_timeout=None):
    """(network, node) from `argv` = [script, PORT, EDS, NODE_ID]: the hub on 127.0.0.1:PORT, channel can0."""
    port, eds, node_id = int(argv[1]), argv[2], int(argv[3])
    network = canopen.Network()
    network.connect(interface="socketcand", host="127.0.0.1", port=port, channel="can0")
    node = canopen.RemoteNode(node_id, eds)
    if sdo_timeout is not None:
        node.sdo.RESPONSE_TIMEOUT = sdo_timeout
    network.add_node(node)
    return network, node
