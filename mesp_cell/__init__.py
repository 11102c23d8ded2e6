"""MESP Cell runtime: the `mesp` console, processes on the bus, drivers, jobs, calibration."""
