"""One module per `dynsplines` subcommand, each with `register(subparsers)`: argument glue only."""
