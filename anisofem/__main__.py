import sys
import warnings

from .cli import main, one_line_warning

warnings.formatwarning = one_line_warning
sys.exit(main())
