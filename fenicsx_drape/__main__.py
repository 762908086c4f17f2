import sys

from fenicsx_drape.cli import main

sys.exit(main())
