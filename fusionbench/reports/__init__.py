"""Reports: the pages and figures of a run and of the conformance matrix."""
