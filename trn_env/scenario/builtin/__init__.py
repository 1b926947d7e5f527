"""Built-in scenario files and their schema."""
