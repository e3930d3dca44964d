"""`python -m graspkit` is the `graspkit` command."""
import sys

from graspkit.cli import main

sys.exit(main())
