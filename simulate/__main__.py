import sys

try:
    from simulate.cli import main
except KeyboardInterrupt:
    # Ctrl-C while the modules load: one line, as once the command runs
    print("error: interrupted before the command started", file=sys.stderr)
    sys.exit(130)

sys.exit(main())
