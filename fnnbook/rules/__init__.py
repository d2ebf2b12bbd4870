"""Claim rules: one small function per claim ID, taking the measured numbers and returning its result.

Every rule returns a :class:`fnnbook.results.ClaimResult` with the claim's ``checks``, ``guarantees`` and
``rule`` (and the ``numbers`` it derives, where it derives some); the notebook adds what only it knows and
writes it: ``sec3.s1(...).replace(numbers=..., figure=...)``.  ``checks`` decide the verdict and can each
fail on a plausible run; ``guarantees`` hold by construction, by a theorem with constants measured on the
same run, or by self-consistency, never count, and a false one stops the run
(:class:`~fnnbook.results.GuaranteeFailed`).

Modules: ``sec3`` (S1-S11), ``sec4`` (D1-D4), ``bottle`` (O1-O2), ``quadrotor`` (Q1-Q6), ``beyond`` (B1, and
B2-B3, which the scoreboard computes from every task's results).
"""
