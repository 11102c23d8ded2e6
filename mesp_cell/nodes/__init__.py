"""The cell's processes: one module per node, each with ``main(argv)``.

Every node is a ``LifecycleNode`` (configure, activate, deactivate, shutdown) with a liveliness
token and a heartbeat; the launcher starts them as ``python -m mesp_cell.nodes.<module>
--name NAME --bus JSON --params JSON``.
"""
