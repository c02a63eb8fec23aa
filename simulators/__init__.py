"""Byte-level device simulators, scene model, transports and fault injection.

Importing this package registers the ``sim://`` pyserial URL handler, so that
``serial.serial_for_url("sim://selspot?cameras=4&leds=32")`` returns a port
wired to a simulated SPX camera system (see ``docs/simulators.md``).
"""

import serial

_HANDLERS = "spotlab.simulators.transports"
if _HANDLERS not in serial.protocol_handler_packages:
    serial.protocol_handler_packages.append(_HANDLERS)
