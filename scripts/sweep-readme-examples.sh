#!/bin/bash
# The three sweep examples of docs/studies.md ("Sweep examples"), as they were run for its tables
# and charts (each folder's sweep.svg is copied to docs/sweep/).
# Usage: scripts/sweep-readme-examples.sh [OUT_DIR] (default runs/); binpick on PATH or $BINPICK.
set -euo pipefail
bp=${BINPICK:-binpick}
out=${1:-runs}
# 1. The cup diameter for A, 4 to 12 mm (a relay 7 mm high: which cups seal on its sides?).
"$bp" sweep --workpieces A --set workpiece.gripper.cup_diameter_m=0.004:0.012:0.002 --seeds 1-3 --deterministic --out "$out"
# 2. The sensor's latency (measurement + recognition), 0.3 / 0.7 / 1.1 s, all six workpieces.
"$bp" sweep --set sensor.latency_s=0.3,0.7,1.1 --deterministic --out "$out"
# 3. The place tray swung about J1 from 90 to 180 degrees away from the pick tray (pick tray at
#    azimuth 77.5 deg; the place tray kept 0.4565 m from the base axis as in the default cell,
#    at azimuth 77.5 - 90, - 120, - 150, - 180 deg; its yaw unchanged).
"$bp" sweep --set 'place_tray.tray.center_m=[0.446,-0.099,0.006],[0.336,-0.309,0.006],[0.137,-0.435,0.006],[-0.099,-0.446,0.006]' \
  --deterministic --out "$out"
