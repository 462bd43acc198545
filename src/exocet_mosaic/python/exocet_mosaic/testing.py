"""Helpers shared by the Python tests of Exocet (rostest checkers): an independent WGS 84 -> UTM conversion to check
GeographicLib's, the exact text of a ROS time as the nodes write it, and the pid of a node of this test's master."""
import math
import xmlrpc.client


def lat_lon_to_utm(lat_deg, lon_deg, zone, northern):
    """WGS 84 -> UTM by Krueger's series to 6th order in n (Karney 2011): independent of GeographicLib, which the
    node uses, and accurate to well under a micrometre within a zone and some degrees beyond."""
    a = 6378137.0
    f = 1.0 / 298.257223563
    n = f / (2.0 - f)
    n2, n3, n4, n5, n6 = n ** 2, n ** 3, n ** 4, n ** 5, n ** 6
    big_a = a / (1.0 + n) * (1.0 + n2 / 4.0 + n4 / 64.0 + n6 / 256.0)
    alpha = [
        n / 2 - 2 * n2 / 3 + 5 * n3 / 16 + 41 * n4 / 180 - 127 * n5 / 288 + 7891 * n6 / 37800,
        13 * n2 / 48 - 3 * n3 / 5 + 557 * n4 / 1440 + 281 * n5 / 630 - 1983433 * n6 / 1935360,
        61 * n3 / 240 - 103 * n4 / 140 + 15061 * n5 / 26880 + 167603 * n6 / 181440,
        49561 * n4 / 161280 - 179 * n5 / 168 + 6601661 * n6 / 7257600,
        34729 * n5 / 80640 - 3418889 * n6 / 1995840,
        212378941 * n6 / 319334400,
    ]
    e = 2.0 * math.sqrt(n) / (1.0 + n)
    phi = math.radians(lat_deg)
    lam = math.radians(lon_deg - (6.0 * zone - 183.0))
    lam = math.atan2(math.sin(lam), math.cos(lam))
    t = math.sinh(math.atanh(math.sin(phi)) - e * math.atanh(e * math.sin(phi)))
    xi_p = math.atan2(t, math.cos(lam))
    eta_p = math.atanh(math.sin(lam) / math.sqrt(1.0 + t * t))
    xi, eta = xi_p, eta_p
    for j, aj in enumerate(alpha, start=1):
        xi += aj * math.sin(2 * j * xi_p) * math.cosh(2 * j * eta_p)
        eta += aj * math.cos(2 * j * xi_p) * math.sinh(2 * j * eta_p)
    k0 = 0.9996
    return 500000.0 + k0 * big_a * eta, (0.0 if northern else 10000000.0) + k0 * big_a * xi


def utm_to_lat_lon(easting_m, northing_m, zone, northern):
    """UTM -> WGS 84 by Newton iterations on lat_lon_to_utm (numerical Jacobian): to well under a millimetre."""
    lat = (northing_m - (0.0 if northern else 10000000.0)) / 111000.0
    lon = 6.0 * zone - 183.0 + (easting_m - 500000.0) / (111000.0 * max(0.1, math.cos(math.radians(lat))))
    for _ in range(20):
        e, n = lat_lon_to_utm(lat, lon, zone, northern)
        d = 1e-6
        e_lat, n_lat = lat_lon_to_utm(lat + d, lon, zone, northern)
        e_lon, n_lon = lat_lon_to_utm(lat, lon + d, zone, northern)
        j = [[(e_lat - e) / d, (e_lon - e) / d], [(n_lat - n) / d, (n_lon - n) / d]]
        det = j[0][0] * j[1][1] - j[0][1] * j[1][0]
        re, rn = easting_m - e, northing_m - n
        lat += (j[1][1] * re - j[0][1] * rn) / det
        lon += (-j[1][0] * re + j[0][0] * rn) / det
        if abs(re) < 1e-5 and abs(rn) < 1e-5:
            break
    return lat, lon


def stamp_text(stamp):
    """A ROS time as the loggers print it: seconds and nanoseconds, exactly."""
    return '%d.%09d' % (stamp.secs, stamp.nsecs)


class _TimeoutTransport(xmlrpc.client.Transport):
    def __init__(self, timeout_s):
        super().__init__()
        self.timeout_s = timeout_s

    def make_connection(self, host):
        connection = super().make_connection(host)
        connection.timeout = self.timeout_s
        return connection


def node_pid(node, timeout_s=2.0):
    """Pid of the node registered as `node` with this process's master (ROS_MASTER_URI), asked to the node itself
    through its XML-RPC API; None when it is not registered or does not answer (killed, not up yet). A process found
    by its name on the machine (pgrep) could be another test's node, under another master."""
    import rosgraph  # only the tests that need it import ROS
    name = node if node.startswith('/') else '/' + node
    try:
        uri = rosgraph.Master('/exocet_test_node_pid').lookupNode(name)
        code, _, pid = xmlrpc.client.ServerProxy(uri, transport=_TimeoutTransport(timeout_s)).getPid(
            '/exocet_test_node_pid')
        return int(pid) if code == 1 else None
    except Exception:  # not registered, refused, timed out: no answer
        return None
