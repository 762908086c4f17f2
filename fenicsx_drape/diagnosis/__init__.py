"""Where a model is judged against measurements: compare, diagnose, the ledger of versions."""
