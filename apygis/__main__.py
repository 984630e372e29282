"""``python -m apygis`` runs the command line."""

from apygis.cli import main

if __name__ == "__main__":
    main()
