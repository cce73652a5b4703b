#!/bin/sh
# Render the synthetic footage (footage/ is not committed), track it into tracks.csv and check the tracks
# against the ground truth; then run: bayes-disc sample sample.yaml
set -e
cd "$(dirname "$0")"
bayes-disc render render.yaml
bayes-disc track track.yaml
python3 check_tracks.py tracks.csv truth.csv
