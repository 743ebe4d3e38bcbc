"""Tools for a user's recording: sensor identification (Allan deviation and its fit), the consistency check of a
recording against its model, and their reports."""
