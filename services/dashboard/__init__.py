"""The dashboard service: a web page, its endpoints and GET /metrics."""
