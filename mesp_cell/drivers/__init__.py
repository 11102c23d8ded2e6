"""Device drivers: the UR5e (RTDE) and its twin, the extruder (Modbus TCP, serial) and its emulator.

Third-party device libraries (ur-rtde, pymodbus, pyserial) are imported lazily, inside the
driver that needs them.
"""
