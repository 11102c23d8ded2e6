"""The extruder controller's Modbus register map (holding registers, 0-based addresses).

See REGISTERS.md next to this file for the operator's version of the same table. A float32 takes
two registers, high word first (big-endian words and bytes); a u32 likewise.
"""

from __future__ import annotations

import struct

# Host -> controller
COMMAND = 0          # u16 command word, bits CMD_*
RATE_SET = 1         # float32 (1-2), mm^3/s, rate set-point
HOST_HEARTBEAT = 3   # u16, the host increments it at >= 10 Hz; a stall trips FAULT_WATCHDOG
WATCHDOG_MS = 4      # u16, ms, watchdog timeout (0 = off), default 500
# Controller -> host
STATUS = 10          # u16 status word, bits ST_*
FAULT = 11           # u16 fault bits (messages.FAULT_*)
RATE = 12            # float32 (12-13), mm^3/s, measured rate
VOLUME = 14          # u32 (14-15), 0.01 mm^3, volume totaliser since power-up
CTRL_HEARTBEAT = 16  # u16, the controller increments it every control cycle
# Emulator only (absent on the real controller): fault injection
INJECT = 100         # u16: 0 none, 1 disconnect the link, 2 stall the motor, 3 freeze the
                     # server (requests unanswered), 4 slip (the screw turns at half the set-point)
INJECT_TIME = 101    # u16, 0.1 s units, how long the injected fault lasts (0 = until cleared)

SIZE = 128           # registers served by the emulator
READ_BLOCK = (STATUS, 7)  # one read returns STATUS .. CTRL_HEARTBEAT

CMD_RUN = 1 << 0     # 1 = run at the set-point, 0 = stop
CMD_RESET = 1 << 1   # rising edge clears latched faults
CMD_ESTOP = 1 << 2   # 1 = emergency stop: motor off, FAULT_ESTOP latched

ST_RUNNING = 1 << 0  # motor on
ST_AT_SET = 1 << 1   # measured rate within AT_SET_BAND of the set-point
ST_FAULT = 1 << 2    # a fault is latched
ST_READY = 1 << 3    # powered, no fault

INJECT_DISCONNECT = 1
INJECT_STALL = 2
INJECT_FREEZE = 3
INJECT_SLIP = 4

#: the controller's accuracy of its measured rate: "at set-point" (ST_AT_SET) within this
#: fraction of the set-point once settled (the robot's flow check uses the same band)
AT_SET_BAND = 0.05


def float_to_regs(value: float) -> list[int]:
    """float32 -> [high word, low word]."""
    hi, lo = struct.unpack(">HH", struct.pack(">f", value))
    return [hi, lo]


def regs_to_float(regs: list[int] | tuple[int, ...]) -> float:
    """[high word, low word] -> float."""
    return float(struct.unpack(">f", struct.pack(">HH", regs[0] & 0xFFFF, regs[1] & 0xFFFF))[0])


def u32_to_regs(value: int) -> list[int]:
    """u32 -> [high word, low word] (wraps modulo 2^32)."""
    value &= 0xFFFFFFFF
    return [value >> 16, value & 0xFFFF]


def regs_to_u32(regs: list[int] | tuple[int, ...]) -> int:
    """[high word, low word] -> u32."""
    return ((regs[0] & 0xFFFF) << 16) | (regs[1] & 0xFFFF)
