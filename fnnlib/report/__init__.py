"""Reporting: claim verdicts, results JSONs and the scoreboard."""
from fnnlib.report.claims import VERDICTS, claim_result, read_results, verdict_from_checks, write_results

__all__ = ["VERDICTS", "claim_result", "read_results", "verdict_from_checks", "write_results"]
