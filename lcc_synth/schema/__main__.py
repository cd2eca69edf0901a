"""``python -m lcc_synth.schema > problems/REFERENCE.md``: print the problem-file reference."""

from __future__ import annotations

import sys

from lcc_synth.schema import reference_markdown

if __name__ == "__main__":
    sys.stdout.write(reference_markdown())
