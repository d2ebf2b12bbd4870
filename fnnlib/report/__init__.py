"""Reporting: claim verdicts, results JSONs and the scoreboard."""
from fnnlib.report.claims import (VERDICTS, GuaranteeFailed, claim_result, headline_number, read_results,
                                  verdict_from_checks, write_results)

__all__ = ["VERDICTS", "GuaranteeFailed", "claim_result", "headline_number", "read_results", "verdict_from_checks",
           "write_results"]
