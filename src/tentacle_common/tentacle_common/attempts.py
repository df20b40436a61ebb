"""
Bounded attempts at one request/reply exchange, kept in step with the device.

A timeout or a garbled reply leaves an exchange ambiguous: the device may still answer,
late, and may have acted. Before the next request the line is drained until it has been
quiet for the device's worst turnaround (a late reply must never answer a later request),
and a request that succeeds after an ambiguous attempt is confirmed by a read-back: its
reply could still have been a stale one. A refusal (Refused) is a clean answer: the line is
in step, and the request is seen as refused.

A set whose value can go stale while it is retried (a zeroing request landed meanwhile)
carries ``still_wanted``: asked right before every attempt, so a retry never re-sends a value
nobody wants any more (Superseded says so, and whether the device may have taken it).
"""

from tentacle_common.errors import (ExchangeFailed, FrameError, Refused, ReplyTimeout,
                                    Superseded)


class Attempts:
    """The retry policy of one device on one line; counts what happened."""

    def __init__(self, line, *, retries, max_turnaround_s, fault=ExchangeFailed):
        """
        Bind to a line.

        :param line: a SerialLine (or a line with its methods)
        :param retries: attempts after the first before ``fault`` is raised
        :param max_turnaround_s: the device's worst time to answer (s)
        :param fault: the ExchangeFailed subclass to raise when attempts run out
        """
        self.line = line
        self.retries = int(retries)
        self.max_turnaround_s = float(max_turnaround_s)
        self.fault = fault
        self.counters = {'commands': 0, 'retries': 0, 'refusals': 0, 'timeouts': 0,
                         'garbled': 0, 'stale_bytes': 0, 'unconfirmed': 0}
        self.out_of_step = False  # an unanswered request may still be answered

    def resync(self):
        """Drop stale input now, without waiting for quiet (at connect)."""
        self.line.discard_input()
        self.out_of_step = False

    def run(self, what, attempt, verify=None, still_wanted=None):
        """
        Return attempt() once it succeeds, within 1 + retries attempts.

        :param what: the request's name, for messages
        :param attempt: sends the request and returns its parsed reply; raises ReplyTimeout,
            FrameError or Refused
        :param verify: after an ambiguous attempt, confirms a success by a read-back;
            returns '' or what is wrong
        :param still_wanted: asked right before each attempt (after any drain); False drops
            the request
        :raises ExchangeFailed: (the ``fault`` class) when every attempt failed
        :raises Superseded: still_wanted() said no before an attempt
        """
        last = None
        ambiguous = False
        for n in range(1 + self.retries):
            if n:
                self.counters['retries'] += 1
            self.counters['commands'] += 1
            try:
                if self.out_of_step:
                    self.counters['stale_bytes'] += self.line.discard_input(
                        quiet_s=self.max_turnaround_s)
                    self.out_of_step = False
                if still_wanted is not None and not still_wanted():
                    raise Superseded(f'{self.line.path}: {what} no longer wanted '
                                     f'(before attempt {n + 1})', ambiguous=ambiguous)
                result = attempt()
                problem = verify() if ambiguous and verify is not None else ''
                if not problem:
                    return result
                self.counters['unconfirmed'] += 1
                self.out_of_step = True
                last = f'read-back after an ambiguous reply: {problem}'
            except Refused as exc:
                self.counters['refusals'] += 1
                last = exc
            except ReplyTimeout as exc:
                self.counters['timeouts'] += 1
                last = exc
                self.out_of_step = ambiguous = True
            except FrameError as exc:
                self.counters['garbled'] += 1
                last = exc
                self.out_of_step = ambiguous = True
        raise self.fault(f'{self.line.path}: {what} failed after {1 + self.retries} '
                         f'attempts: {last}')
