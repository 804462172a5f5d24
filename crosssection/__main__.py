import sys

from crosssection.cli import main

sys.exit(main())
