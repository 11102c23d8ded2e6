"""The operator's console: an HTTP/WebSocket API and a web page served by the console node."""
