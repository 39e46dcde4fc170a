"""maxon EPOS2 CANopen constants: object dictionary, CiA 402 device control, operating modes,
error codes, CiA 301 SDO abort codes and COB-IDs. No ROS, no CAN I/O.

Every protocol number of the project lives here; the emulator (`epos2_emulator`) and the motor
driver (CANopen master) both import it. Where each number comes from (maxon's EPOS2 Firmware
Specification as quoted by public EPOS2 drivers, CiA 301 / CiA 402) is tabulated in
docs/canopen.md. Names are stable: add, don't rename.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from enum import Enum, IntEnum

# --------------------------------------------------------------------------------------------
# CiA 301 data types (the numbers EDS files use in DataType=) and access types
# --------------------------------------------------------------------------------------------


class DataType(IntEnum):
    BOOLEAN = 0x0001
    INTEGER8 = 0x0002
    INTEGER16 = 0x0003
    INTEGER32 = 0x0004
    UNSIGNED8 = 0x0005
    UNSIGNED16 = 0x0006
    UNSIGNED32 = 0x0007
    VISIBLE_STRING = 0x0009


#: struct format (little endian) of each fixed-size data type
DATA_TYPE_FORMAT: dict[DataType, str] = {
    DataType.BOOLEAN: "<?",
    DataType.INTEGER8: "<b",
    DataType.INTEGER16: "<h",
    DataType.INTEGER32: "<i",
    DataType.UNSIGNED8: "<B",
    DataType.UNSIGNED16: "<H",
    DataType.UNSIGNED32: "<I",
}


def data_type_size(data_type: DataType) -> int | None:
    """Size in bytes of a fixed-size data type; None for strings."""
    fmt = DATA_TYPE_FORMAT.get(DataType(data_type))
    return None if fmt is None else struct.calcsize(fmt)


def data_type_range(data_type: DataType) -> tuple[int, int] | None:
    """Smallest and largest value of an integer data type; None for strings."""
    size = data_type_size(data_type)
    if size is None:
        return None
    if DataType(data_type) in (DataType.INTEGER8, DataType.INTEGER16, DataType.INTEGER32):
        return -(1 << (8 * size - 1)), (1 << (8 * size - 1)) - 1
    if DataType(data_type) == DataType.BOOLEAN:
        return 0, 1
    return 0, (1 << (8 * size)) - 1


class Access(str, Enum):
    RO = "ro"
    WO = "wo"
    RW = "rw"
    CONST = "const"

    @property
    def readable(self) -> bool:
        return self is not Access.WO

    @property
    def writable(self) -> bool:
        return self in (Access.RW, Access.WO)


# --------------------------------------------------------------------------------------------
# Object indices. CiA 301 communication profile (0x1000-0x1FFF)
# --------------------------------------------------------------------------------------------

DEVICE_TYPE = 0x1000
ERROR_REGISTER = 0x1001
ERROR_HISTORY = 0x1003                  # pre-defined error field: sub0 count (write 0 clears), sub1..5
COB_ID_SYNC = 0x1005
COMMUNICATION_CYCLE_PERIOD = 0x1006
MANUFACTURER_DEVICE_NAME = 0x1008
GUARD_TIME = 0x100C
LIFE_TIME_FACTOR = 0x100D
STORE_PARAMETERS = 0x1010
RESTORE_DEFAULT_PARAMETERS = 0x1011
COB_ID_EMCY = 0x1014
CONSUMER_HEARTBEAT_TIME = 0x1016        # sub1: (producer node id << 16) | time [ms]
PRODUCER_HEARTBEAT_TIME = 0x1017        # [ms]
IDENTITY = 0x1018                       # sub1 vendor id, sub2 product code, sub3 revision, sub4 serial
SDO_SERVER_PARAMETER = 0x1200           # sub1 COB-ID client->server, sub2 COB-ID server->client
RPDO_COMMUNICATION = 0x1400             # + n (0..3): sub1 COB-ID, sub2 transmission type
RPDO_MAPPING = 0x1600                   # + n (0..3): sub0 count, sub1..8 (index << 16 | sub << 8 | bits)
TPDO_COMMUNICATION = 0x1800             # + n: sub1 COB-ID, sub2 type, sub3 inhibit [100 us], sub5 event timer [ms]
TPDO_MAPPING = 0x1A00                   # + n (0..3)
PDO_COUNT = 4                           # EPOS2: 4 RPDOs and 4 TPDOs
PDO_MAX_ENTRIES = 8                     # mapping entries per PDO (CiA 301)

ERROR_HISTORY_LENGTH = 5                # EPOS2 keeps 5 entries in 0x1003

# sub-indices of the PDO communication parameter records
PDO_COB_ID_SUB = 1
PDO_TRANSMISSION_TYPE_SUB = 2
PDO_INHIBIT_TIME_SUB = 3
PDO_EVENT_TIMER_SUB = 5

# --------------------------------------------------------------------------------------------
# maxon EPOS2 manufacturer-specific objects (0x2000-0x5FFF)
# --------------------------------------------------------------------------------------------

NODE_ID = 0x2000
CAN_BITRATE = 0x2001
VERSION = 0x2003                        # sub1 software, sub2 hardware version
VERSION_SOFTWARE_SUB = 1
VERSION_HARDWARE_SUB = 2
ENCODER_COUNTER = 0x2020
CURRENT_ACTUAL_VALUE_AVERAGED = 0x2027  # INTEGER16 [mA]
VELOCITY_ACTUAL_VALUE_AVERAGED = 0x2028 # INTEGER32 [rpm]
CURRENT_MODE_SETTING_VALUE = 0x2030     # INTEGER16 [mA], the setpoint of Current Mode (-3)
CURRENT_DEMAND_VALUE = 0x2031           # INTEGER32 [mA]
POSITION_MODE_SETTING_VALUE = 0x2062    # INTEGER32 [qc], the setpoint of Position Mode (-1)
VELOCITY_MODE_SETTING_VALUE = 0x206B    # INTEGER32 [rpm], the setpoint of Velocity Mode (-2)
FOLLOWING_ERROR_ACTUAL_VALUE = 0x20F4   # INTEGER16 [qc]
SENSOR_CONFIGURATION = 0x2210           # sub1 encoder pulse number, sub2 position sensor type, sub4 polarity
SENSOR_PULSE_NUMBER_SUB = 1
SENSOR_TYPE_SUB = 2
SENSOR_POLARITY_SUB = 4

# --------------------------------------------------------------------------------------------
# CiA 402 device profile objects (0x6000-0x9FFF) as the EPOS2 implements them
# --------------------------------------------------------------------------------------------

ABORT_CONNECTION_OPTION_CODE = 0x6007
ERROR_CODE = 0x603F                     # UNSIGNED16: the code of the last error (0 when none)
CONTROLWORD = 0x6040
STATUSWORD = 0x6041
MODES_OF_OPERATION = 0x6060             # INTEGER8, see OperationMode
MODES_OF_OPERATION_DISPLAY = 0x6061
POSITION_DEMAND_VALUE = 0x6062          # INTEGER32 [qc]
POSITION_ACTUAL_VALUE = 0x6064          # INTEGER32 [qc]
MAX_FOLLOWING_ERROR = 0x6065            # UNSIGNED32 [qc]
VELOCITY_SENSOR_ACTUAL_VALUE = 0x6069
VELOCITY_DEMAND_VALUE = 0x606B          # INTEGER32 [rpm]
VELOCITY_ACTUAL_VALUE = 0x606C          # INTEGER32 [rpm]
CURRENT_ACTUAL_VALUE = 0x6078           # INTEGER16 [mA]
SOFTWARE_POSITION_LIMIT = 0x607D        # sub1 min, sub2 max [qc]
CURRENT_CONTROL_PARAMETERS = 0x60F6     # sub1 P, sub2 I (EPOS2 units)
VELOCITY_CONTROL_PARAMETERS = 0x60F9    # sub1 P, sub2 I
POSITION_CONTROL_PARAMETERS = 0x60FB    # sub1 P, sub2 I, sub3 D, sub4 velocity FF, sub5 acceleration FF
GAIN_P_SUB = 1
GAIN_I_SUB = 2
GAIN_D_SUB = 3
GAIN_VELOCITY_FF_SUB = 4
GAIN_ACCELERATION_FF_SUB = 5
MOTOR_TYPE = 0x6402
MOTOR_DATA = 0x6410
MOTOR_CONTINUOUS_CURRENT_LIMIT_SUB = 1  # UNSIGNED16 [mA]
MOTOR_OUTPUT_CURRENT_LIMIT_SUB = 2      # UNSIGNED16 [mA] (peak); EPOS2 default: 2 x continuous
MOTOR_POLE_PAIR_NUMBER_SUB = 3          # UNSIGNED8
MOTOR_MAX_SPEED_CURRENT_MODE_SUB = 4    # UNSIGNED32 [rpm]
MOTOR_THERMAL_TIME_CONSTANT_SUB = 5     # UNSIGNED16 [0.1 s]
SUPPORTED_DRIVE_MODES = 0x6502

# motor types of 0x6402 (EPOS2)
MOTOR_TYPE_BRUSHED_DC = 1
MOTOR_TYPE_EC_SINUSOIDAL = 10
MOTOR_TYPE_EC_BLOCK = 11

# --------------------------------------------------------------------------------------------
# Identity and fixed values of the emulated drive
# --------------------------------------------------------------------------------------------

#: 0x1000: CiA 402 (0x0192 = 402) drive profile, additional information 0x0002 (servo drive)
DEVICE_TYPE_VALUE = 0x00020192
MAXON_VENDOR_ID = 0x000000FB            # maxon motor ag, CiA vendor id
DEVICE_NAME = "EPOS2"
SOFTWARE_VERSION = 0x2126               # emulated firmware version reported in 0x2003 sub1
HARDWARE_VERSION = 0x6220               # EPOS2 70/10 hardware version (emulated)

#: 0x6065 default of the emulated drive: no following-error limit until the master sets one
MAX_FOLLOWING_ERROR_OFF = 0xFFFFFFFF

#: Store / restore signatures of 0x1010 / 0x1011 (ASCII "save" / "load", CiA 301)
STORE_SIGNATURE = 0x65766173
RESTORE_SIGNATURE = 0x64616F6C

# --------------------------------------------------------------------------------------------
# Operating modes (0x6060 / 0x6061)
# --------------------------------------------------------------------------------------------


class OperationMode(IntEnum):
    """EPOS2 modes of operation: the CiA 402 profile modes and maxon's negative modes."""

    NONE = 0                            # not a mode: the value before any mode is set
    PROFILE_POSITION = 1
    PROFILE_VELOCITY = 3
    HOMING = 6
    INTERPOLATED_POSITION = 7
    POSITION = -1                       # Position Mode, setpoint 0x2062
    VELOCITY = -2                       # Velocity Mode, setpoint 0x206B
    CURRENT = -3                        # Current Mode, setpoint 0x2030
    MASTER_ENCODER = -5
    STEP_DIRECTION = -6


#: The modes the emulated drive regulates (the driver needs current and position)
EMULATED_MODES = (OperationMode.CURRENT, OperationMode.POSITION)

# --------------------------------------------------------------------------------------------
# CiA 402 device control: controlword commands and statusword states (EPOS2 values)
# --------------------------------------------------------------------------------------------


class ControlwordBit(IntEnum):
    SWITCH_ON = 0
    ENABLE_VOLTAGE = 1
    QUICK_STOP = 2                      # active low: 0 requests quick stop
    ENABLE_OPERATION = 3
    FAULT_RESET = 7                     # rising edge
    HALT = 8


class Command(IntEnum):
    """Controlword values of the CiA 402 device control commands."""

    SHUTDOWN = 0x0006
    SWITCH_ON = 0x0007
    SWITCH_ON_AND_ENABLE = 0x000F
    DISABLE_VOLTAGE = 0x0000
    QUICK_STOP = 0x0002
    DISABLE_OPERATION = 0x0007
    ENABLE_OPERATION = 0x000F
    FAULT_RESET = 0x0080


class StatuswordBit(IntEnum):
    READY_TO_SWITCH_ON = 0
    SWITCHED_ON = 1
    OPERATION_ENABLED = 2
    FAULT = 3
    VOLTAGE_ENABLED = 4                 # EPOS2: power stage on
    QUICK_STOP = 5                      # active low: 0 while quick stop is active
    SWITCH_ON_DISABLED = 6
    WARNING = 7
    OFFSET_CURRENT_MEASURED = 8         # EPOS2-specific, set once the current offset is measured
    REMOTE = 9
    TARGET_REACHED = 10
    INTERNAL_LIMIT_ACTIVE = 11
    REFRESH_CYCLE = 14                  # EPOS2-specific: refresh cycle of the power stage
    POSITION_REFERENCED = 15            # position referenced to home


class State(str, Enum):
    """CiA 402 states as the EPOS2 reports them."""

    START = "START"
    NOT_READY_TO_SWITCH_ON = "NOT_READY_TO_SWITCH_ON"
    SWITCH_ON_DISABLED = "SWITCH_ON_DISABLED"
    READY_TO_SWITCH_ON = "READY_TO_SWITCH_ON"
    SWITCHED_ON = "SWITCHED_ON"
    REFRESH = "REFRESH"
    MEASURE_INIT = "MEASURE_INIT"
    OPERATION_ENABLED = "OPERATION_ENABLED"
    QUICK_STOP_ACTIVE = "QUICK_STOP_ACTIVE"
    FAULT_REACTION_ACTIVE_DISABLED = "FAULT_REACTION_ACTIVE_DISABLED"
    FAULT_REACTION_ACTIVE_ENABLED = "FAULT_REACTION_ACTIVE_ENABLED"
    FAULT = "FAULT"


#: The statusword the EPOS2 shows in each state (EPOS2 Firmware Specification, device states)
STATUSWORD_OF_STATE: dict[State, int] = {
    State.START: 0x0000,
    State.NOT_READY_TO_SWITCH_ON: 0x0100,
    State.SWITCH_ON_DISABLED: 0x0140,
    State.READY_TO_SWITCH_ON: 0x0121,
    State.SWITCHED_ON: 0x0123,
    State.REFRESH: 0x4123,
    State.MEASURE_INIT: 0x4133,
    State.OPERATION_ENABLED: 0x0137,
    State.QUICK_STOP_ACTIVE: 0x0117,
    State.FAULT_REACTION_ACTIVE_DISABLED: 0x010F,
    State.FAULT_REACTION_ACTIVE_ENABLED: 0x011F,
    State.FAULT: 0x0108,
}

#: Bits of the statusword that carry the state (the rest is mode-specific or informative)
STATUSWORD_STATE_MASK = 0x417F


def decode_statusword(statusword: int) -> State:
    """The EPOS2 state a statusword shows (decision tree of the EPOS2 state table)."""
    sw = int(statusword) & 0xFFFF
    bit = lambda b: bool(sw & (1 << b))  # noqa: E731 - local shorthand
    if bit(StatuswordBit.REFRESH_CYCLE):
        return State.MEASURE_INIT if bit(StatuswordBit.VOLTAGE_ENABLED) else State.REFRESH
    if not bit(StatuswordBit.OFFSET_CURRENT_MEASURED):
        return State.START
    if bit(StatuswordBit.SWITCH_ON_DISABLED):
        return State.SWITCH_ON_DISABLED
    if bit(StatuswordBit.FAULT):
        if bit(StatuswordBit.VOLTAGE_ENABLED):
            return State.FAULT_REACTION_ACTIVE_ENABLED
        if bit(StatuswordBit.OPERATION_ENABLED):
            return State.FAULT_REACTION_ACTIVE_DISABLED
        return State.FAULT
    if bit(StatuswordBit.QUICK_STOP):
        if bit(StatuswordBit.OPERATION_ENABLED):
            return State.OPERATION_ENABLED
        if bit(StatuswordBit.SWITCHED_ON):
            return State.SWITCHED_ON
        if bit(StatuswordBit.READY_TO_SWITCH_ON):
            return State.READY_TO_SWITCH_ON
        return State.NOT_READY_TO_SWITCH_ON
    if bit(StatuswordBit.OPERATION_ENABLED):
        return State.QUICK_STOP_ACTIVE
    return State.NOT_READY_TO_SWITCH_ON


# --------------------------------------------------------------------------------------------
# Error register (0x1001) bits and EPOS2 error codes (EMCY, 0x1003, 0x603F)
# --------------------------------------------------------------------------------------------


class ErrorRegisterBit(IntEnum):
    GENERIC = 0x01
    CURRENT = 0x02
    VOLTAGE = 0x04
    TEMPERATURE = 0x08
    COMMUNICATION = 0x10
    DEVICE_PROFILE = 0x20
    MOTION = 0x80                       # EPOS2: manufacturer-specific (motion error)


@dataclass(frozen=True)
class ErrorInfo:
    code: int
    text: str
    register: int                       # the error register bits the EPOS2 sets with it


def _errors(*rows: tuple[int, str, int]) -> dict[int, ErrorInfo]:
    return {code: ErrorInfo(code, text, reg) for code, text, reg in rows}


#: EPOS2 error codes with their texts and error register bits
EPOS2_ERRORS: dict[int, ErrorInfo] = _errors(
    (0x0000, "No error", 0x00),
    (0x1000, "Generic error", 0x01),
    (0x2310, "Over current error", 0x02),
    (0x3210, "Over voltage error", 0x04),
    (0x3220, "Under voltage", 0x04),
    (0x4210, "Over temperature", 0x08),
    (0x5113, "Supply voltage (+5V) too low", 0x04),
    (0x5114, "Supply voltage output stage too low", 0x04),
    (0x6100, "Internal software error", 0x20),
    (0x6320, "Software parameter error", 0x20),
    (0x7320, "Position sensor error", 0x20),
    (0x8110, "CAN overrun error (objects lost)", 0x10),
    (0x8111, "CAN overrun error", 0x10),
    (0x8120, "CAN passive mode error", 0x10),
    (0x8130, "CAN life guard error (heartbeat or node guarding)", 0x10),
    (0x8150, "CAN transmit COB-ID collision", 0x10),
    (0x81FD, "CAN bus off", 0x10),
    (0x81FE, "CAN Rx queue overrun", 0x10),
    (0x81FF, "CAN Tx queue overrun", 0x10),
    (0x8210, "CAN PDO length error", 0x10),
    (0x8611, "Following error", 0x20),
    (0xFF01, "Hall sensor error", 0x80),
    (0xFF02, "Index processing error", 0x80),
    (0xFF03, "Encoder resolution error", 0x80),
    (0xFF04, "Hall sensor not found error", 0x80),
    (0xFF06, "Negative limit switch error", 0x80),
    (0xFF07, "Positive limit switch error", 0x80),
    (0xFF08, "Hall angle detection error", 0x80),
    (0xFF09, "Software position limit error", 0x80),
    (0xFF0A, "Position sensor breach", 0x80),
    (0xFF0B, "System overloaded", 0x20),
    (0xFF0C, "Interpolated position mode error", 0x80),
    (0xFF0D, "Auto tuning identification error", 0x80),
)

ERROR_NONE = 0x0000
ERROR_GENERIC = 0x1000
ERROR_OVER_CURRENT = 0x2310
ERROR_LIFE_GUARD = 0x8130               # heartbeat consumer timeout, node guarding
ERROR_PDO_LENGTH = 0x8210
ERROR_FOLLOWING = 0x8611


def error_text(code: int) -> str:
    """Text of an EPOS2 error code (also for codes the table does not know)."""
    info = EPOS2_ERRORS.get(int(code))
    return info.text if info else f"Unknown error 0x{int(code):04X}"


def error_register_bits(code: int) -> int:
    """Error register bits for an error code: the table's, else generic."""
    info = EPOS2_ERRORS.get(int(code))
    return info.register if info else ErrorRegisterBit.GENERIC


# --------------------------------------------------------------------------------------------
# SDO protocol (CiA 301) and abort codes
# --------------------------------------------------------------------------------------------

# client command specifiers (bits 7..5 of byte 0)
SDO_CCS_DOWNLOAD_SEGMENT = 0
SDO_CCS_INITIATE_DOWNLOAD = 1
SDO_CCS_INITIATE_UPLOAD = 2
SDO_CCS_UPLOAD_SEGMENT = 3
SDO_CS_ABORT = 4
SDO_CCS_BLOCK_UPLOAD = 5
SDO_CCS_BLOCK_DOWNLOAD = 6
# server command specifiers
SDO_SCS_UPLOAD_SEGMENT = 0
SDO_SCS_DOWNLOAD_SEGMENT = 1
SDO_SCS_INITIATE_UPLOAD = 2
SDO_SCS_INITIATE_DOWNLOAD = 3
SDO_ABORT_BYTE = 0x80
SDO_TOGGLE_BIT = 0x10
SDO_EXPEDITED_BIT = 0x02
SDO_SIZE_BIT = 0x01
SDO_SEGMENT_LAST_BIT = 0x01
SDO_FRAME_LENGTH = 8


class SdoAbort(IntEnum):
    TOGGLE_BIT_NOT_ALTERNATED = 0x05030000
    TIMEOUT = 0x05040000
    UNKNOWN_COMMAND = 0x05040001
    INVALID_BLOCK_SIZE = 0x05040002
    INVALID_SEQUENCE_NUMBER = 0x05040003
    CRC_ERROR = 0x05040004
    OUT_OF_MEMORY = 0x05040005
    UNSUPPORTED_ACCESS = 0x06010000
    WRITE_ONLY = 0x06010001
    READ_ONLY = 0x06010002
    OBJECT_DOES_NOT_EXIST = 0x06020000
    CANNOT_BE_MAPPED = 0x06040041
    PDO_LENGTH_EXCEEDED = 0x06040042
    PARAMETER_INCOMPATIBILITY = 0x06040043
    INTERNAL_INCOMPATIBILITY = 0x06040047
    HARDWARE_ERROR = 0x06060000
    LENGTH_MISMATCH = 0x06070010
    LENGTH_TOO_HIGH = 0x06070012
    LENGTH_TOO_LOW = 0x06070013
    SUBINDEX_DOES_NOT_EXIST = 0x06090011
    INVALID_VALUE = 0x06090030
    VALUE_TOO_HIGH = 0x06090031
    VALUE_TOO_LOW = 0x06090032
    MAX_LESS_THAN_MIN = 0x06090036
    GENERAL_ERROR = 0x08000000
    CANNOT_TRANSFER = 0x08000020
    LOCAL_CONTROL = 0x08000021
    DEVICE_STATE = 0x08000022
    NO_OBJECT_DICTIONARY = 0x08000023
    # maxon-specific
    WRONG_NMT_STATE = 0x0F00FFC0
    ILLEGAL_COMMAND = 0x0F00FFBF
    PASSWORD_INCORRECT = 0x0F00FFBE
    NOT_IN_SERVICE_MODE = 0x0F00FFBC
    NODE_ID_ERROR = 0x0F00FFB9


SDO_ABORT_TEXT: dict[int, str] = {
    SdoAbort.TOGGLE_BIT_NOT_ALTERNATED: "Toggle bit not alternated",
    SdoAbort.TIMEOUT: "SDO protocol timed out",
    SdoAbort.UNKNOWN_COMMAND: "Client/server command specifier not valid or unknown",
    SdoAbort.INVALID_BLOCK_SIZE: "Invalid block size",
    SdoAbort.INVALID_SEQUENCE_NUMBER: "Invalid sequence number",
    SdoAbort.CRC_ERROR: "CRC error",
    SdoAbort.OUT_OF_MEMORY: "Out of memory",
    SdoAbort.UNSUPPORTED_ACCESS: "Unsupported access to an object",
    SdoAbort.WRITE_ONLY: "Attempt to read a write only object",
    SdoAbort.READ_ONLY: "Attempt to write a read only object",
    SdoAbort.OBJECT_DOES_NOT_EXIST: "Object does not exist in the object dictionary",
    SdoAbort.CANNOT_BE_MAPPED: "Object cannot be mapped to the PDO",
    SdoAbort.PDO_LENGTH_EXCEEDED: "The number and length of the objects to be mapped would exceed PDO length",
    SdoAbort.PARAMETER_INCOMPATIBILITY: "General parameter incompatibility",
    SdoAbort.INTERNAL_INCOMPATIBILITY: "General internal incompatibility in the device",
    SdoAbort.HARDWARE_ERROR: "Access failed due to a hardware error",
    SdoAbort.LENGTH_MISMATCH: "Data type does not match, length of service parameter does not match",
    SdoAbort.LENGTH_TOO_HIGH: "Data type does not match, length of service parameter too high",
    SdoAbort.LENGTH_TOO_LOW: "Data type does not match, length of service parameter too low",
    SdoAbort.SUBINDEX_DOES_NOT_EXIST: "Sub-index does not exist",
    SdoAbort.INVALID_VALUE: "Invalid value for parameter (download only)",
    SdoAbort.VALUE_TOO_HIGH: "Value of parameter written too high (download only)",
    SdoAbort.VALUE_TOO_LOW: "Value of parameter written too low (download only)",
    SdoAbort.MAX_LESS_THAN_MIN: "Maximum value is less than minimum value",
    SdoAbort.GENERAL_ERROR: "General error",
    SdoAbort.CANNOT_TRANSFER: "Data cannot be transferred or stored to the application",
    SdoAbort.LOCAL_CONTROL: "Data cannot be transferred or stored to the application because of local control",
    SdoAbort.DEVICE_STATE: "Data cannot be transferred or stored to the application because of the present device state",
    SdoAbort.NO_OBJECT_DICTIONARY: "Object dictionary dynamic generation fails or no object dictionary is present",
    SdoAbort.WRONG_NMT_STATE: "The device is in wrong NMT state",
    SdoAbort.ILLEGAL_COMMAND: "The RS232 command is illegal",
    SdoAbort.PASSWORD_INCORRECT: "The password is not correct",
    SdoAbort.NOT_IN_SERVICE_MODE: "The device is not in service mode",
    SdoAbort.NODE_ID_ERROR: "Error Node-ID",
}


def sdo_abort_text(code: int) -> str:
    return SDO_ABORT_TEXT.get(int(code), f"Unknown SDO abort code 0x{int(code):08X}")


# --------------------------------------------------------------------------------------------
# NMT (CiA 301)
# --------------------------------------------------------------------------------------------


class NmtCommand(IntEnum):
    START = 0x01
    STOP = 0x02
    ENTER_PRE_OPERATIONAL = 0x80
    RESET_NODE = 0x81
    RESET_COMMUNICATION = 0x82


class NmtState(IntEnum):
    """NMT states with the value the heartbeat carries."""

    BOOTUP = 0x00
    STOPPED = 0x04
    OPERATIONAL = 0x05
    PRE_OPERATIONAL = 0x7F


NMT_BROADCAST_NODE = 0                  # node id 0 in an NMT command addresses every node

# --------------------------------------------------------------------------------------------
# COB-IDs (CiA 301 pre-defined connection set)
# --------------------------------------------------------------------------------------------

NMT_COB_ID = 0x000
SYNC_COB_ID = 0x080
EMCY_BASE = 0x080
TPDO_BASES = (0x180, 0x280, 0x380, 0x480)
RPDO_BASES = (0x200, 0x300, 0x400, 0x500)
SDO_TX_BASE = 0x580                     # server -> client (drive answers)
SDO_RX_BASE = 0x600                     # client -> server (master requests)
HEARTBEAT_BASE = 0x700
COB_ID_INVALID_BIT = 0x80000000         # bit 31 of a PDO / EMCY COB-ID: not valid (disabled)
COB_ID_NO_RTR_BIT = 0x40000000          # bit 30 of a TPDO COB-ID: no RTR allowed
COB_ID_MASK_11BIT = 0x7FF
NODE_ID_MIN = 1
NODE_ID_MAX = 127


def _check_node(node_id: int) -> int:
    if not NODE_ID_MIN <= int(node_id) <= NODE_ID_MAX:
        raise ValueError(f"CANopen node id must be {NODE_ID_MIN}..{NODE_ID_MAX}, got {node_id}")
    return int(node_id)


def emcy_cob_id(node_id: int) -> int:
    return EMCY_BASE + _check_node(node_id)


def tpdo_cob_id(pdo: int, node_id: int) -> int:
    """COB-ID of TPDO `pdo` (1..4) of a node."""
    if not 1 <= pdo <= PDO_COUNT:
        raise ValueError(f"TPDO number must be 1..{PDO_COUNT}, got {pdo}")
    return TPDO_BASES[pdo - 1] + _check_node(node_id)


def rpdo_cob_id(pdo: int, node_id: int) -> int:
    """COB-ID of RPDO `pdo` (1..4) of a node."""
    if not 1 <= pdo <= PDO_COUNT:
        raise ValueError(f"RPDO number must be 1..{PDO_COUNT}, got {pdo}")
    return RPDO_BASES[pdo - 1] + _check_node(node_id)


def sdo_tx_cob_id(node_id: int) -> int:
    return SDO_TX_BASE + _check_node(node_id)


def sdo_rx_cob_id(node_id: int) -> int:
    return SDO_RX_BASE + _check_node(node_id)


def heartbeat_cob_id(node_id: int) -> int:
    return HEARTBEAT_BASE + _check_node(node_id)


def pdo_mapping_entry(index: int, subindex: int, bits: int) -> int:
    """A PDO mapping entry (0x1600.. / 0x1A00.. sub 1..8): index << 16 | subindex << 8 | bits."""
    return (int(index) & 0xFFFF) << 16 | (int(subindex) & 0xFF) << 8 | (int(bits) & 0xFF)


def split_pdo_mapping_entry(entry: int) -> tuple[int, int, int]:
    """(index, subindex, bits) of a PDO mapping entry."""
    return (entry >> 16) & 0xFFFF, (entry >> 8) & 0xFF, entry & 0xFF


# PDO transmission types (0x1400/0x1800 sub2)
TRANSMISSION_SYNC_ACYCLIC = 0
TRANSMISSION_SYNC_MAX = 240            # 1..240: every n-th SYNC
TRANSMISSION_RTR_SYNC = 252
TRANSMISSION_RTR_EVENT = 253
TRANSMISSION_EVENT_MANUFACTURER = 254
TRANSMISSION_EVENT = 255

# --------------------------------------------------------------------------------------------
# Object dictionary of the emulated EPOS2
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ODEntry:
    """One (index, subindex) of the dictionary. `default` is the factory value (for COB-IDs the
    value without the node id; `plus_node_id` says to add it)."""

    index: int
    subindex: int
    name: str
    data_type: DataType
    access: Access
    default: int | str = 0
    pdo_mappable: bool = False
    unit: str = ""
    plus_node_id: bool = False


_U8, _U16, _U32 = DataType.UNSIGNED8, DataType.UNSIGNED16, DataType.UNSIGNED32
_I8, _I16, _I32 = DataType.INTEGER8, DataType.INTEGER16, DataType.INTEGER32
_RO, _RW, _CONST = Access.RO, Access.RW, Access.CONST

#: Default PDO mapping of the emulated drive (our choice, see docs/canopen.md):
#: {pdo number: (COB-ID base, transmission type, enabled, ((index, subindex, bits), ...))}
DEFAULT_RPDO_MAPPING: dict[int, tuple[int, bool, tuple[tuple[int, int, int], ...]]] = {
    1: (TRANSMISSION_EVENT, True, ((CONTROLWORD, 0, 16), (CURRENT_MODE_SETTING_VALUE, 0, 16))),
    2: (TRANSMISSION_EVENT, True, ((CONTROLWORD, 0, 16), (POSITION_MODE_SETTING_VALUE, 0, 32))),
    3: (TRANSMISSION_EVENT, True, ((CONTROLWORD, 0, 16), (MODES_OF_OPERATION, 0, 8))),
    4: (TRANSMISSION_EVENT, False, ()),
}
DEFAULT_TPDO_MAPPING: dict[int, tuple[int, bool, tuple[tuple[int, int, int], ...]]] = {
    1: (1, True, ((STATUSWORD, 0, 16), (POSITION_ACTUAL_VALUE, 0, 32))),
    2: (1, True, ((VELOCITY_ACTUAL_VALUE_AVERAGED, 0, 32), (CURRENT_ACTUAL_VALUE_AVERAGED, 0, 16))),
    3: (1, True, ((CURRENT_ACTUAL_VALUE, 0, 16), (MODES_OF_OPERATION_DISPLAY, 0, 8), (ERROR_CODE, 0, 16))),
    4: (TRANSMISSION_EVENT, False, ()),
}


def _pdo_entries() -> list[ODEntry]:
    rows: list[ODEntry] = []
    for kind, comm, mapping, bases, defaults in (
        ("RPDO", RPDO_COMMUNICATION, RPDO_MAPPING, RPDO_BASES, DEFAULT_RPDO_MAPPING),
        ("TPDO", TPDO_COMMUNICATION, TPDO_MAPPING, TPDO_BASES, DEFAULT_TPDO_MAPPING),
    ):
        for n in range(PDO_COUNT):
            trans, enabled, entries = defaults[n + 1]
            cob = bases[n] | (0 if enabled else COB_ID_INVALID_BIT)
            name = f"{kind}{n + 1}"
            last_sub = PDO_EVENT_TIMER_SUB if kind == "TPDO" else PDO_TRANSMISSION_TYPE_SUB
            rows.append(ODEntry(comm + n, 0, f"{name} parameter: highest sub-index", _U8, _CONST, last_sub))
            rows.append(ODEntry(comm + n, PDO_COB_ID_SUB, f"{name} COB-ID", _U32, _RW, cob, plus_node_id=True))
            rows.append(ODEntry(comm + n, PDO_TRANSMISSION_TYPE_SUB, f"{name} transmission type", _U8, _RW, trans))
            if kind == "TPDO":
                rows.append(ODEntry(comm + n, PDO_INHIBIT_TIME_SUB, f"{name} inhibit time", _U16, _RW, 0, unit="100 us"))
                rows.append(ODEntry(comm + n, PDO_EVENT_TIMER_SUB, f"{name} event timer", _U16, _RW, 0, unit="ms"))
            rows.append(ODEntry(mapping + n, 0, f"{name} number of mapped objects", _U8, _RW, len(entries)))
            for sub in range(1, PDO_MAX_ENTRIES + 1):
                value = pdo_mapping_entry(*entries[sub - 1]) if sub <= len(entries) else 0
                rows.append(ODEntry(mapping + n, sub, f"{name} mapped object {sub}", _U32, _RW, value))
    return rows


OBJECT_DICTIONARY: tuple[ODEntry, ...] = (
    ODEntry(DEVICE_TYPE, 0, "Device type", _U32, _CONST, DEVICE_TYPE_VALUE),
    ODEntry(ERROR_REGISTER, 0, "Error register", _U8, _RO, 0, pdo_mappable=True),
    ODEntry(ERROR_HISTORY, 0, "Number of errors", _U8, _RW, 0),
    *(ODEntry(ERROR_HISTORY, s, f"Error history {s}", _U32, _RO, 0) for s in range(1, ERROR_HISTORY_LENGTH + 1)),
    ODEntry(COB_ID_SYNC, 0, "COB-ID SYNC", _U32, _RW, SYNC_COB_ID),
    ODEntry(COMMUNICATION_CYCLE_PERIOD, 0, "Communication cycle period", _U32, _RW, 0, unit="us"),
    ODEntry(MANUFACTURER_DEVICE_NAME, 0, "Manufacturer device name", DataType.VISIBLE_STRING, _CONST, DEVICE_NAME),
    ODEntry(GUARD_TIME, 0, "Guard time", _U16, _RW, 0, unit="ms"),
    ODEntry(LIFE_TIME_FACTOR, 0, "Life time factor", _U8, _RW, 0),
    ODEntry(STORE_PARAMETERS, 0, "Store parameters: highest sub-index", _U8, _RO, 1),
    ODEntry(STORE_PARAMETERS, 1, "Save all parameters", _U32, _RW, 1),
    ODEntry(RESTORE_DEFAULT_PARAMETERS, 0, "Restore default parameters: highest sub-index", _U8, _RO, 1),
    ODEntry(RESTORE_DEFAULT_PARAMETERS, 1, "Restore all default parameters", _U32, _RW, 1),
    ODEntry(COB_ID_EMCY, 0, "COB-ID EMCY", _U32, _RW, EMCY_BASE, plus_node_id=True),
    ODEntry(CONSUMER_HEARTBEAT_TIME, 0, "Consumer heartbeat time: number of entries", _U8, _RO, 1),
    ODEntry(CONSUMER_HEARTBEAT_TIME, 1, "Consumer heartbeat time", _U32, _RW, 0),
    ODEntry(PRODUCER_HEARTBEAT_TIME, 0, "Producer heartbeat time", _U16, _RW, 0, unit="ms"),
    ODEntry(IDENTITY, 0, "Identity object: number of entries", _U8, _RO, 4),
    ODEntry(IDENTITY, 1, "Vendor ID", _U32, _RO, MAXON_VENDOR_ID),
    ODEntry(IDENTITY, 2, "Product code", _U32, _RO, 0),
    ODEntry(IDENTITY, 3, "Revision number", _U32, _RO, 0),
    ODEntry(IDENTITY, 4, "Serial number", _U32, _RO, 0),
    ODEntry(SDO_SERVER_PARAMETER, 0, "SDO server parameter: number of entries", _U8, _RO, 2),
    ODEntry(SDO_SERVER_PARAMETER, 1, "COB-ID client to server", _U32, _RO, SDO_RX_BASE, plus_node_id=True),
    ODEntry(SDO_SERVER_PARAMETER, 2, "COB-ID server to client", _U32, _RO, SDO_TX_BASE, plus_node_id=True),
    *_pdo_entries(),
    ODEntry(NODE_ID, 0, "Node ID", _U8, _RW, 1),
    ODEntry(CAN_BITRATE, 0, "CAN bitrate", _U16, _RW, 0),
    ODEntry(VERSION, 0, "Version: number of entries", _U8, _RO, 2),
    ODEntry(VERSION, VERSION_SOFTWARE_SUB, "Software version", _U16, _RO, SOFTWARE_VERSION),
    ODEntry(VERSION, VERSION_HARDWARE_SUB, "Hardware version", _U16, _RO, HARDWARE_VERSION),
    ODEntry(ENCODER_COUNTER, 0, "Encoder counter", _U16, _RO, 0, pdo_mappable=True, unit="qc"),
    ODEntry(CURRENT_ACTUAL_VALUE_AVERAGED, 0, "Current actual value averaged", _I16, _RO, 0, True, "mA"),
    ODEntry(VELOCITY_ACTUAL_VALUE_AVERAGED, 0, "Velocity actual value averaged", _I32, _RO, 0, True, "rpm"),
    ODEntry(CURRENT_MODE_SETTING_VALUE, 0, "Current mode setting value", _I16, _RW, 0, True, "mA"),
    ODEntry(CURRENT_DEMAND_VALUE, 0, "Current demand value", _I32, _RO, 0, True, "mA"),
    ODEntry(POSITION_MODE_SETTING_VALUE, 0, "Position mode setting value", _I32, _RW, 0, True, "qc"),
    ODEntry(VELOCITY_MODE_SETTING_VALUE, 0, "Velocity mode setting value", _I32, _RW, 0, True, "rpm"),
    ODEntry(FOLLOWING_ERROR_ACTUAL_VALUE, 0, "Following error actual value", _I16, _RO, 0, True, "qc"),
    ODEntry(SENSOR_CONFIGURATION, 0, "Sensor configuration: number of entries", _U8, _RO, 4),
    ODEntry(SENSOR_CONFIGURATION, SENSOR_PULSE_NUMBER_SUB, "Encoder pulse number", _U32, _RW, 500),
    ODEntry(SENSOR_CONFIGURATION, SENSOR_TYPE_SUB, "Position sensor type", _U16, _RW, 1),
    ODEntry(SENSOR_CONFIGURATION, 3, "Internal use", _U32, _RW, 0),
    ODEntry(SENSOR_CONFIGURATION, SENSOR_POLARITY_SUB, "Position sensor polarity", _U16, _RW, 0),
    ODEntry(ABORT_CONNECTION_OPTION_CODE, 0, "Abort connection option code", _I16, _RW, 2),
    ODEntry(ERROR_CODE, 0, "Error code", _U16, _RO, 0, pdo_mappable=True),
    ODEntry(CONTROLWORD, 0, "Controlword", _U16, _RW, 0, pdo_mappable=True),
    ODEntry(STATUSWORD, 0, "Statusword", _U16, _RO, 0, pdo_mappable=True),
    ODEntry(MODES_OF_OPERATION, 0, "Modes of operation", _I8, _RW, 0, pdo_mappable=True),
    ODEntry(MODES_OF_OPERATION_DISPLAY, 0, "Modes of operation display", _I8, _RO, 0, pdo_mappable=True),
    ODEntry(POSITION_DEMAND_VALUE, 0, "Position demand value", _I32, _RO, 0, True, "qc"),
    ODEntry(POSITION_ACTUAL_VALUE, 0, "Position actual value", _I32, _RO, 0, True, "qc"),
    ODEntry(MAX_FOLLOWING_ERROR, 0, "Max following error", _U32, _RW, MAX_FOLLOWING_ERROR_OFF, unit="qc"),
    ODEntry(VELOCITY_SENSOR_ACTUAL_VALUE, 0, "Velocity sensor actual value", _I32, _RO, 0, True, "qc/0.1ms"),
    ODEntry(VELOCITY_DEMAND_VALUE, 0, "Velocity demand value", _I32, _RO, 0, True, "rpm"),
    ODEntry(VELOCITY_ACTUAL_VALUE, 0, "Velocity actual value", _I32, _RO, 0, True, "rpm"),
    ODEntry(CURRENT_ACTUAL_VALUE, 0, "Current actual value", _I16, _RO, 0, True, "mA"),
    ODEntry(SOFTWARE_POSITION_LIMIT, 0, "Software position limit: number of entries", _U8, _RO, 2),
    ODEntry(SOFTWARE_POSITION_LIMIT, 1, "Min position limit", _I32, _RW, -(1 << 31), unit="qc"),
    ODEntry(SOFTWARE_POSITION_LIMIT, 2, "Max position limit", _I32, _RW, (1 << 31) - 1, unit="qc"),
    ODEntry(CURRENT_CONTROL_PARAMETERS, 0, "Current control parameter set: number of entries", _U8, _RO, 2),
    ODEntry(CURRENT_CONTROL_PARAMETERS, GAIN_P_SUB, "Current regulator P-gain", _I16, _RW, 0),
    ODEntry(CURRENT_CONTROL_PARAMETERS, GAIN_I_SUB, "Current regulator I-gain", _I16, _RW, 0),
    ODEntry(VELOCITY_CONTROL_PARAMETERS, 0, "Velocity control parameter set: number of entries", _U8, _RO, 2),
    ODEntry(VELOCITY_CONTROL_PARAMETERS, GAIN_P_SUB, "Velocity regulator P-gain", _I16, _RW, 0),
    ODEntry(VELOCITY_CONTROL_PARAMETERS, GAIN_I_SUB, "Velocity regulator I-gain", _I16, _RW, 0),
    ODEntry(POSITION_CONTROL_PARAMETERS, 0, "Position control parameter set: number of entries", _U8, _RO, 5),
    ODEntry(POSITION_CONTROL_PARAMETERS, GAIN_P_SUB, "Position regulator P-gain", _I16, _RW, 0),
    ODEntry(POSITION_CONTROL_PARAMETERS, GAIN_I_SUB, "Position regulator I-gain", _I16, _RW, 0),
    ODEntry(POSITION_CONTROL_PARAMETERS, GAIN_D_SUB, "Position regulator D-gain", _I16, _RW, 0),
    ODEntry(POSITION_CONTROL_PARAMETERS, GAIN_VELOCITY_FF_SUB, "Velocity feed forward factor", _U16, _RW, 0),
    ODEntry(POSITION_CONTROL_PARAMETERS, GAIN_ACCELERATION_FF_SUB, "Acceleration feed forward factor", _U16, _RW, 0),
    ODEntry(MOTOR_TYPE, 0, "Motor type", _U16, _RW, MOTOR_TYPE_EC_SINUSOIDAL),
    ODEntry(MOTOR_DATA, 0, "Motor data: number of entries", _U8, _RO, 5),
    ODEntry(MOTOR_DATA, MOTOR_CONTINUOUS_CURRENT_LIMIT_SUB, "Continuous current limit", _U16, _RW, 5000, unit="mA"),
    ODEntry(MOTOR_DATA, MOTOR_OUTPUT_CURRENT_LIMIT_SUB, "Output current limit", _U16, _RW, 10000, unit="mA"),
    ODEntry(MOTOR_DATA, MOTOR_POLE_PAIR_NUMBER_SUB, "Pole pair number", _U8, _RW, 1),
    ODEntry(MOTOR_DATA, MOTOR_MAX_SPEED_CURRENT_MODE_SUB, "Maximal speed in current mode", _U32, _RW, 25000, unit="rpm"),
    ODEntry(MOTOR_DATA, MOTOR_THERMAL_TIME_CONSTANT_SUB, "Thermal time constant winding", _U16, _RW, 40, unit="0.1 s"),
    ODEntry(SUPPORTED_DRIVE_MODES, 0, "Supported drive modes", _U32, _RO, 0),
)


def object_dictionary(node_id: int) -> dict[tuple[int, int], ODEntry]:
    """The dictionary as {(index, subindex): entry} with node-id dependent defaults resolved."""
    node = _check_node(node_id)
    table: dict[tuple[int, int], ODEntry] = {}
    for entry in OBJECT_DICTIONARY:
        if entry.plus_node_id:
            entry = ODEntry(entry.index, entry.subindex, entry.name, entry.data_type, entry.access,
                            int(entry.default) + node, entry.pdo_mappable, entry.unit, False)
        elif (entry.index, entry.subindex) == (NODE_ID, 0):
            entry = ODEntry(entry.index, 0, entry.name, entry.data_type, entry.access, node)
        table[(entry.index, entry.subindex)] = entry
    return table


def mappable(entry: ODEntry) -> bool:
    """Whether an entry may be mapped into a PDO."""
    return entry.pdo_mappable


#: Names of the multi-entry objects (records)
RECORD_NAMES: dict[int, str] = {
    ERROR_HISTORY: "Pre-defined error field",
    STORE_PARAMETERS: "Store parameters",
    RESTORE_DEFAULT_PARAMETERS: "Restore default parameters",
    CONSUMER_HEARTBEAT_TIME: "Consumer heartbeat time",
    IDENTITY: "Identity object",
    SDO_SERVER_PARAMETER: "Server SDO parameter",
    **{RPDO_COMMUNICATION + n: f"RPDO{n + 1} communication parameter" for n in range(PDO_COUNT)},
    **{RPDO_MAPPING + n: f"RPDO{n + 1} mapping parameter" for n in range(PDO_COUNT)},
    **{TPDO_COMMUNICATION + n: f"TPDO{n + 1} communication parameter" for n in range(PDO_COUNT)},
    **{TPDO_MAPPING + n: f"TPDO{n + 1} mapping parameter" for n in range(PDO_COUNT)},
    VERSION: "Version",
    SENSOR_CONFIGURATION: "Sensor configuration",
    SOFTWARE_POSITION_LIMIT: "Software position limit",
    CURRENT_CONTROL_PARAMETERS: "Current control parameter set",
    VELOCITY_CONTROL_PARAMETERS: "Velocity control parameter set",
    POSITION_CONTROL_PARAMETERS: "Position control parameter set",
    MOTOR_DATA: "Motor data",
}


def eds_text() -> str:
    """The emulated drive's dictionary as a CiA 306 EDS (for CANopen masters such as `canopen`).

    COB-IDs are written as $NODEID+base; values the emulator takes from config/hardware.yaml
    (current limits, gains, heartbeat time) appear with their factory defaults.
    """
    groups: dict[int, list[ODEntry]] = {}
    for entry in OBJECT_DICTIONARY:
        groups.setdefault(entry.index, []).append(entry)
    lines = [
        "[FileInfo]", "FileName=epos2_emulated.eds", "FileVersion=1", "Description=Emulated maxon EPOS2 "
        "(hopper_ros.canbus.epos2_emulator), generated by epos2_objects.eds_text()", "",
        "[DeviceInfo]", "VendorName=maxon motor ag (emulated)", f"VendorNumber=0x{MAXON_VENDOR_ID:08X}",
        f"ProductName={DEVICE_NAME}", "BaudRate_1000=1", "SimpleBootUpSlave=1", "Granularity=8",
        "NrOfRXPDO=4", "NrOfTXPDO=4", "LSS_Supported=0", "",
    ]
    mandatory = [i for i in groups if i in (DEVICE_TYPE, ERROR_REGISTER, IDENTITY)]
    optional = [i for i in groups if i < 0x2000 and i not in mandatory]
    manufacturer = [i for i in groups if 0x2000 <= i < 0x6000]
    profile = [i for i in groups if i >= 0x6000]
    for title, indices in (("MandatoryObjects", mandatory), ("OptionalObjects", optional + profile),
                           ("ManufacturerObjects", manufacturer)):
        lines += [f"[{title}]", f"SupportedObjects={len(indices)}"]
        lines += [f"{n}=0x{index:04X}" for n, index in enumerate(indices, start=1)]
        lines.append("")

    def body(entry: ODEntry) -> list[str]:
        if entry.plus_node_id:
            default = f"$NODEID+0x{int(entry.default):X}"
        elif entry.data_type == DataType.VISIBLE_STRING:
            default = str(entry.default)
        elif int(entry.default) < 0:
            default = str(int(entry.default))
        else:
            default = f"0x{int(entry.default):X}"
        return [f"ParameterName={entry.name}", "ObjectType=0x7", f"DataType=0x{int(entry.data_type):04X}",
                f"AccessType={entry.access.value}", f"DefaultValue={default}",
                f"PDOMapping={1 if entry.pdo_mappable else 0}"]

    for index, entries in groups.items():
        if len(entries) == 1 and entries[0].subindex == 0:
            lines += [f"[{index:04X}]", *body(entries[0]), ""]
            continue
        name = RECORD_NAMES.get(index, entries[0].name)
        lines += [f"[{index:04X}]", f"ParameterName={name}", "ObjectType=0x9", f"SubNumber={len(entries)}", ""]
        for entry in entries:
            lines += [f"[{index:04X}sub{entry.subindex:X}]", *body(entry), ""]
    return "\n".join(lines)
