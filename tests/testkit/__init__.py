"""Helpers shared by the tests (FMU drivers, oracles, reference cases, process checks); no tests here."""
