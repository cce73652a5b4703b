"""``python -m bayes_disc.video track|render CONFIG`` (same as ``bayes-disc track|render``)."""
import sys

from .cli import main

sys.exit(main())
