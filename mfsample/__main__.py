"""`python -m mfsample COMMAND [flags]`: the `mfsample` command (`mfsample.cli`)."""

from mfsample.cli import main

if __name__ == "__main__":
  main()
