import warnings

from anisofem.cli import one_line_warning

from .cli import main

warnings.formatwarning = one_line_warning
main()
