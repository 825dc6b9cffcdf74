"""``python -m lfmbench.cli <command>``: the same as the ``lfmbench`` command."""
from lfmbench.cli import main

main()
