"""The cell's message bus: zenoh sessions (``session``), key expressions (``keys``) and the
message codec (``codec``).

Only ``mesp_cell`` imports this package; libraries (slicer, planner, sim) never do. Import the
submodules directly (``from mesp_cell.bus.session import Bus``): ``mesp_cell.messages`` needs the
codec while the session needs the messages.
"""
