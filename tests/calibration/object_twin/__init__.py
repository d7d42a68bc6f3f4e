"""Tests of the object twin (issue 14, section 3)."""
