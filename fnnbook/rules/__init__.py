"""Claim rules: one small function per claim ID, taking the measured numbers and returning its checks.

Each rule returns ``{"checks": ..., "guarantees": ..., "rule": ...}``, ready to be passed to
:func:`fnnlib.results.claim_result` (``F.claim_result("S1", **sec3.s1(...), numbers=..., figure=...)``).
``checks`` decide the verdict and can each fail on a plausible run; ``guarantees`` hold by construction,
by a theorem with constants measured on the same run, or by self-consistency, and never count.

Modules: ``sec3`` (S1-S11), ``sec4`` (D1-D4), ``bottle`` (O1-O2), ``quadrotor`` (Q1-Q6), ``beyond`` (B1).
"""
