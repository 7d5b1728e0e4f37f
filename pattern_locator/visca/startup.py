"""
The EVI-D31's start-up: Address Set, IF_Clear, power on, the end of the initialisation, shutter.

ROS-free. :class:`StartUp` runs the sequence from
:meth:`~pattern_locator.visca.camera.EviD31.start` (the caller's thread) and
again after every reconnect (the transport's callback thread), and says
when the camera is ready on the current connection. A step that fails is
retried every 50 ms until the deadline; closing the camera ends it at once.
After a Network Change (a power cycle, or another camera on the chain) it
sends Address Set and sets the requested shutter again, once the camera's
initialisation lets it: a power-up returns the camera to full auto exposure.
The shutter never fails a start-up: a refusal or a camera that keeps
quiet about it is reported (:attr:`~pattern_locator.visca.camera.EviD31.exposure`)
and the camera is ready all the same.
"""

import logging
import threading
import time
from typing import Callable, Optional, TYPE_CHECKING

from . import protocol as visca
from .exceptions import ViscaCommandError, ViscaConnectionError, ViscaTimeout
from .exposure import apply_shutter

if TYPE_CHECKING:  # pragma: no cover - typing only
    from .camera import EviD31

logger = logging.getLogger(__name__)

# A camera silent this long into a start-up is worth one line to the user.
SILENT_WARNING_S = 1.0
RETRY_PAUSE_S = 0.05


class StartUp:
    """The start-up sequence of one :class:`~pattern_locator.visca.camera.EviD31`."""

    def __init__(self, camera: 'EviD31', power_on_at_start: bool) -> None:
        self._camera = camera
        self.power_on_at_start = power_on_at_start
        self._lock = threading.Lock()
        self._ready = threading.Event()
        self._generation = -1
        self._power_asked = False
        # Until IF_Clear is through, commands are refused at once (it would cancel them).
        self.clearing = False

    @property
    def ready(self) -> bool:
        """Return True when connected and the start-up has finished on this connection."""
        transport = self._camera.transport
        return (self._ready.is_set() and transport.connected
                and self._generation == transport.reconnect_count)

    def forget(self) -> None:
        """Not ready any more (closing)."""
        self._ready.clear()

    def run(self, deadline: float, timeout_s: float, wait_reconnect: bool,
            generation: Optional[int] = None) -> None:
        """
        Run Address Set, IF_Clear, power on, the wait for the initialisation, the shutter.

        ``wait_reconnect``: a lost connection is waited out until ``deadline``
        (``start``) instead of ending the start-up (after a reconnect, where
        the next reconnect brings its own start-up). ``generation``: skip if
        a start-up already ran on that connection.
        """
        camera, transport = self._camera, self._camera.transport
        with self._lock:
            if generation is not None and self._ready.is_set() \
                    and self._generation >= generation:
                return
            self._ready.clear()
            self._power_asked = False
            steps = (
                ('Address Set', lambda: transport.broadcast(visca.address_set())),
                ('IF_Clear', lambda: transport.broadcast(visca.if_clear())),
                ('power on', self._power_step),
                # While it initialises the head refuses commands (not executable).
                ('the end of the initialisation', self._init_step),
            )
            with camera.command_lock:
                self.clearing = True
            try:
                for what, step in steps[:2]:
                    self._retry(deadline, step, what, timeout_s, wait_reconnect)
                    if what == 'Address Set':
                        self._generation = transport.reconnect_count
            finally:
                with camera.command_lock:
                    self.clearing = False
                    camera.forget_motions()
            for what, step in steps[2:]:
                self._retry(deadline, step, what, timeout_s, wait_reconnect)
            if camera.shutter_request is not None:
                # After the initialisation the camera executes commands: a refusal now
                # is final (not waited out).
                self._set_shutter(deadline, False, None)
            self._ready.set()
            logger.info('EVI-D31 on %s ready', camera.port)

    def _retry(self, deadline: float, step: Callable[[], object], what: str,
               timeout_s: float, wait_reconnect: bool) -> None:
        camera = self._camera
        last: object = None
        started = time.monotonic()
        warned = False
        while True:
            if camera.closing:
                raise ViscaConnectionError(f'EVI-D31 on {camera.port}: closed during start-up')
            try:
                if step() is not False:
                    return
                last = 'not yet'
            except ViscaConnectionError as exc:
                if camera.closing or not (wait_reconnect and camera.transport.is_open):
                    raise
                last = exc
            except (ViscaTimeout, ViscaCommandError) as exc:
                last = exc
            now = time.monotonic()
            if now >= deadline:
                error = ViscaConnectionError if isinstance(last, ViscaConnectionError) \
                    else ViscaTimeout
                raise error(f'EVI-D31 on {camera.port}: no {what} within {timeout_s:.1f} s '
                            f'(last: {last})')
            if not warned and now - started > SILENT_WARNING_S and isinstance(
                    last, (ViscaTimeout, ViscaConnectionError)):
                warned = True
                logger.warning('EVI-D31 on %s: no %s yet after %.1f s (is the camera on, the '
                               'cable a null-modem one?): %s', camera.port, what,
                               now - started, last)
            camera.wait_closing(RETRY_PAUSE_S)

    def _power_step(self) -> bool:
        camera = self._camera
        if camera.power_on():
            return True
        if self.power_on_at_start and not self._power_asked:
            logger.info('EVI-D31 on %s in standby: switching it on', camera.port)
            camera.power(True, wait=False)
            self._power_asked = True
        return False

    def _init_step(self) -> bool:
        camera = self._camera
        with camera.command_lock:
            camera.transport.command(visca.pan_tilt_stop(camera.address),
                                     timeout=camera.transport.reply_timeout_s,
                                     duration_s=visca.INSTANT_COMMAND_S)
        camera.position()
        return True

    def _shutter_step(self, deadline: float, wait_initialising: bool,
                      generation: Optional[int] = None) -> bool:
        """
        Set the shutter; True once it is done or given up (the report is kept).

        Retried (False) while the camera answers not executable (only with
        ``wait_initialising``: a power-up's initialisation) or an answer got
        lost, until shortly before ``deadline``; also given up when the
        connection changed under it (``generation``: its reconnect's start-up
        sets the shutter again).
        """
        camera = self._camera
        report = apply_shutter(camera, camera.shutter_request)
        again = report.retryable or (wait_initialising and report.not_executable)
        if again and time.monotonic() + RETRY_PAUSE_S < deadline \
                and (generation is None or generation == camera.transport.reconnect_count):
            return False
        camera.note_exposure(report)
        # Info either way: the owner (the node) turns a failed one into its warning, once.
        logger.info('EVI-D31 on %s: %s', camera.port, report.message)
        return True

    # Transport callbacks (on the transport's callback thread, never the reader) --------------

    def on_network_change(self) -> None:
        """Send Address Set again (the camera may have been power-cycled), then the shutter."""
        camera = self._camera
        try:
            camera.transport.broadcast(visca.address_set())
            logger.info('EVI-D31 on %s: network change, address set again', camera.port)
        except visca.ViscaError as exc:
            logger.warning('EVI-D31 on %s: address set after network change failed: %s',
                           camera.port, exc)
            return
        if camera.shutter_request is not None:
            self._reapply_shutter()

    def _reapply_shutter(self) -> None:
        """Set the shutter again after a Network Change, waiting out an initialisation."""
        camera = self._camera
        generation = camera.transport.reconnect_count
        deadline = time.monotonic() + camera.restart_timeout_s
        # Not while a start-up runs: it sets the shutter itself at its end.
        if not self._lock.acquire(timeout=camera.restart_timeout_s):
            return
        try:
            self._set_shutter(deadline, True, generation)
        except visca.ViscaError as exc:
            # The port went away (the reconnect's start-up sets the shutter) or closing.
            if not camera.closing:
                logger.warning('EVI-D31 on %s: shutter after network change failed: %s',
                               camera.port, exc)
        finally:
            self._lock.release()

    def _set_shutter(self, deadline: float, wait_initialising: bool,
                     generation: Optional[int]) -> None:
        """Run :meth:`_shutter_step` until it is done; ViscaConnectionError when closed."""
        camera = self._camera
        while not self._shutter_step(deadline, wait_initialising, generation):
            if camera.wait_closing(RETRY_PAUSE_S):
                raise ViscaConnectionError(f'EVI-D31 on {camera.port}: closed during start-up')

    def on_reconnect(self) -> None:
        """Run the start-up on the new connection."""
        camera = self._camera
        timeout_s = camera.restart_timeout_s
        try:
            self.run(time.monotonic() + timeout_s, timeout_s, wait_reconnect=False,
                     generation=camera.transport.reconnect_count)
        except visca.ViscaError as exc:
            if camera.transport.is_open and not camera.closing:
                logger.warning('EVI-D31 on %s: start-up after reconnect failed: %s',
                               camera.port, exc)
