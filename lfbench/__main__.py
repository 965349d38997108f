import sys

from lfbench.cli import main

sys.exit(main())
