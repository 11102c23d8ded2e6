"""Shared pytest setup: a non-interactive matplotlib backend for figure tests."""

import os

os.environ.setdefault("MPLBACKEND", "Agg")
