"""The package's tests: in virtual time here (no privileges, no network); live tests, which
need root and veth pairs, are run from crates/cli/tests/python_live.rs."""
import os
import sys

EXAMPLES = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "examples")
sys.path.insert(0, EXAMPLES)
