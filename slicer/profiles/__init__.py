"""Bundled extrusion profiles (``<name>.toml``), loaded by ``slicer.extrusion.load_profile``."""

from __future__ import annotations

from importlib import resources

# The profile a fresh cell prints with until a lab activates its own (``mesp profile activate``).
FACTORY = "ecoflex-0030"


def bundled_names() -> list[str]:
    """Names of the bundled profiles (file stems), sorted."""
    root = resources.files(__name__)
    return sorted(p.name[: -len(".toml")] for p in root.iterdir() if p.name.endswith(".toml"))
