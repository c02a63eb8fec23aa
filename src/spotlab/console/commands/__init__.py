"""One module per subcommand of `spotlab`."""
