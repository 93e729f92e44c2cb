"""The operator page (issue 20): a web page served by the ``web`` node of the graph.

Pure modules (no rclpy), each unit-tested:

- :mod:`.params`   the node's parameters, declared once;
- :mod:`.auth`     operator password (scrypt), sessions, CSRF tokens, login rate limit;
- :mod:`.commands` what the page may ask (stow, modes, jog, e-stop, reset, replan,
  home) and the validation that refuses bad input before any service is called;
- :mod:`.live`     the live view (latest message of every topic as JSON), the day
  buffer behind the plots, and how to clear each safety reason;
- :mod:`.bags`     recorded days: list, safe lookup, streamed zip download;
- :mod:`.app`      the aiohttp application (routes, Server-Sent Events, security).

The node (:mod:`sslfr_web.web_node`) wires topics and service clients to them.
"""
