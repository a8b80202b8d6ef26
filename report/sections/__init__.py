"""One module per section of the report page; each builder takes the context and returns HTML."""
