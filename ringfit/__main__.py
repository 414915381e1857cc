import sys

from ringfit.cli import main

sys.exit(main())
