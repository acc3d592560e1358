"""``python -m paper_sim_ros.dataset``: the ``paper_sim_dataset`` command."""
import sys

from .cli import main

sys.exit(main())
