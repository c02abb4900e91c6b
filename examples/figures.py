"""Regenerate the README's figures into docs/figures/ (the same as `python -m wavecore.figures`)."""

from wavecore.figures import main

if __name__ == "__main__":
    raise SystemExit(main())
