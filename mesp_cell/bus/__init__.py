"""The cell's message bus: zenoh sessions (``session``), key expressions (``keys``), the
message codec (``codec``), and its authority: the cell's secret (``secret``), signed payloads
(``signing``), presence that cannot be forged (``presence``) and TLS with access control for a
cell across hosts (``tls``). docs/security.md.

Only ``mesp_cell`` imports this package; libraries (slicer, planner, sim) never do. Import the
submodules directly (``from mesp_cell.bus.session import Bus``): ``mesp_cell.messages`` needs the
codec while the session needs the messages.
"""
