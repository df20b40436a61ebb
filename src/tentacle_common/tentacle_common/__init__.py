"""What every driver shares: parameter tables, spin, logging, diagnostics, serial line, retries."""
