"""Command-line interface: ``lcc-synth COMMAND ...``; one module per command."""
