#!/bin/sh
# Render the synthetic footage (footage/ is not committed) and track it into tracks.csv; then run: bayes-disc sample sample.yaml
cd "$(dirname "$0")" && bayes-disc render render.yaml && bayes-disc track track.yaml
