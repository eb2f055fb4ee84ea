"""The analysis pipeline. Reads datasets only: never imports the twin or hw, never opens the truth folder."""
