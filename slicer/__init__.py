"""Slicer: solid model -> tetrahedral mesh -> curved layers -> width-constrained toolpath.

Pure library: no process, bus or robot code is imported here (design.md).
"""
