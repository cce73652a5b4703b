"""``python -m bayes_disc ...``: the ``bayes-disc`` command line."""
import sys

from .cli import main

sys.exit(main())
