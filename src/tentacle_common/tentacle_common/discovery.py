"""
Who may see and command the rig: a private DDS domain on this machine unless a lab says so.

ROS 2 nodes find each other on a domain (ROS_DOMAIN_ID, 0 when unset: the one every ROS
install on a network shares) over the range ROS_AUTOMATIC_DISCOVERY_RANGE allows (SUBNET
when unset). The rig's scripts default both: the domain DEFAULT_DOMAIN_ID and LOCALHOST, so
a participant on another machine, or on another domain here, sees none of the rig's topics
and commands nothing. Set either in the environment to choose otherwise (a lab PC driving
the rig from another machine: the same ROS_DOMAIN_ID on both, and
ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET). Without DDS security (see the README: SROS2) this is
the only fence. Pure: sets environment variables, before rclpy starts.
"""

DEFAULT_DOMAIN_ID = 57   # not 0: not the domain every other ROS install on a network joins
LOCALHOST = 'LOCALHOST'


def private_by_default(environ):
    """
    Set ROS_DOMAIN_ID and ROS_AUTOMATIC_DISCOVERY_RANGE where unset; return a line saying so.

    :param environ: os.environ (or a copy for a child process), changed in place
    """
    chosen = [name for name in ('ROS_DOMAIN_ID', 'ROS_AUTOMATIC_DISCOVERY_RANGE')
              if name in environ]
    environ.setdefault('ROS_DOMAIN_ID', str(DEFAULT_DOMAIN_ID))
    environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', LOCALHOST)
    how = (f'{" and ".join(chosen)} as the environment sets' if chosen else
           'the defaults: this machine only (to open it: ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET '
           "and a ROS_DOMAIN_ID of the lab's)")
    return (f"DDS discovery {environ['ROS_AUTOMATIC_DISCOVERY_RANGE']}, ROS_DOMAIN_ID "
            f"{environ['ROS_DOMAIN_ID']}: {how}")
