"""Shared test settings."""

from pathlib import Path

#: the real Lytro capture in the shared data folder beside the repository
LYTRO_DIR = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "lytro-f01-img0001"
