"""MAVLink 2 for remarl-fc: a sans-IO codec, an asyncio UDP endpoint and named protocol numbers.

`codec` wraps pymavlink's generated parser and encoder for one explicitly chosen dialect
(ardupilotmega, which includes common and minimal); `udp` is an asyncio datagram endpoint that
feeds it; `consts` names every number the project puts on or reads off the wire.
"""
