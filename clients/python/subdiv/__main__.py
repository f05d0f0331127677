"""python3 -m subdiv ... is the `subdiv` command."""
import sys

from .cli import main

sys.exit(main())
