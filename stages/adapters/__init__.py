"""One module per external library, converting canonical data in and out."""
