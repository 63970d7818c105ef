"""The soak: valid scenarios drawn at random over the whole configuration space
(:mod:`soak.generate`), run, and checked against the promises of their Parquet tables alone
(:mod:`soak.invariants`); a failing scenario is shrunk to a minimal one (:mod:`soak.shrink`).
``dispatch soak`` is its command (:mod:`soak.commands`)."""
