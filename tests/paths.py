"""Where the repository keeps what tests and benchmarks read (nothing outside it)."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "data"
BAGS = DATA / "bags"
HUSKY = BAGS / "robot_localization_husky"
TURTLEBOT3 = BAGS / "fuse_turtlebot3_sim"
IROBOT = ROOT / "schemas" / "msgs" / "irobot_create_msgs"
DEPLOY = ROOT / "deploy"
DOCS = ROOT / "docs"
