"""Core: the base every package builds on, with no algorithm of its own.

The stage values and their files (``stages``, ``artifacts``, ``report``), the user-error type
(``errors``), config loading (``configtools``, ``toml_defaults``), progress reporting
(``progress``), the tolerance object (``tolerance``), the status enums (``status``), the
cell's printing-angle range (``alpha_range``) and the figures' look (``figure_style``).
It imports no other package of the project; slicer, planner, sim and mesp_cell import it.
"""
