"""Flight reports: data extraction from a flight log (data.py) and the HTML page (html.py)."""
