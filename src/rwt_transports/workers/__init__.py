"""The processes of ``rwt serve --workers N``: supervised, counted, placing connections."""
