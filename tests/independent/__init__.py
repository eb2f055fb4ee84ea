"""An independent dataset generator and the test of the loop on its datasets (issue 16 item 1)."""
