"""Board link: the wire protocol, messages, transports (serial, XBee API), the link and the XBee hub."""
