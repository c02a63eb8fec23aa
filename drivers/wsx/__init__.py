"""WSX: spotlab's LED-multiplexed linear-sensor hub over USB (docs/protocols/wsx.md).

Our own protocol in the style of WATSMART/Optotrak, not NDI's. Needs pyusb (the
``usb`` extra, which brings ``libusb-package`` for real hardware).
"""

from spotlab.drivers.wsx.decoding import LAYOUT, WsxDecoder, decoder_from_metadata
from spotlab.drivers.wsx.driver import WsxDriver
from spotlab.drivers.wsx.protocol import PRODUCT_ID, VENDOR_ID, Setup

__all__ = [
    "LAYOUT",
    "PRODUCT_ID",
    "VENDOR_ID",
    "Setup",
    "WsxDecoder",
    "WsxDriver",
    "decoder_from_metadata",
]
