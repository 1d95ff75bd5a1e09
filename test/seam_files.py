"""Two files a user would write: a second controller and a second plant (the seam tests'
fixtures, written to a folder on PYTHONPATH and named ``my_law:Kanayama``, ``my_base:Skid``)."""

#: A second law in a file of its own: Kanayama's classic unicycle tracker (1990), feedforward
#: of the reference's speed and turn rate plus pose-error feedback in the robot frame.
KANAYAMA = '''
import math
from nonfragile_tracker.control.simulation.tracker import Command
from nonfragile_tracker.control.simulation.timing import PeriodEstimator


class Kanayama:
    def __init__(self, config, kx=1.0, ky=4.0, kth=3.0):
        self.config, self.gains, self.timing = config, (kx, ky, kth), PeriodEstimator()
        self.seen = []

    @property
    def horizon(self):
        return 0.0

    def reset(self, v=None):
        pass

    def step(self, x, y, th, ref, measured_speed=None, stamp=None, stamp_ns=None,
             measured_rate=None):
        self.seen.append((x, y, th, ref.t))
        kx, ky, kth = self.gains
        vr = math.hypot(ref.vx, ref.vy)
        wr = (ref.vx * ref.ay - ref.vy * ref.ax) / max(vr * vr, 1e-9)
        dx, dy = ref.x - x, ref.y - y
        ex = math.cos(th) * dx + math.sin(th) * dy
        ey = -math.sin(th) * dx + math.cos(th) * dy
        eth = math.remainder(ref.heading - th, math.tau)
        return Command(v=vr * math.cos(eth) + kx * ex,
                       w=wr + vr * (ky * ey + kth * math.sin(eth)))
'''

#: A second plant in a file of its own: a unicycle whose turn rate is only 70 % of the
#: commanded one (a skid-steer's), exact odometry at every step.
SKID = '''
import math
from nonfragile_tracker.control.simulation.sensors import OdometrySample


class Skid:
    def __init__(self, config, turn_gain=0.7):
        self.config, self.turn_gain = config, turn_gain
        self.reset()

    @property
    def dt(self):
        return self.config.dt

    def reset(self):
        c = self.config
        self.k, self.x, self.y, self.th, self.v, self.w = 0, c.x0, c.y0, c.th0, c.v0, 0.0
        self.cmd = (c.v0, 0.0)

    def command(self, v, w):
        self.cmd = (v, w)

    def advance(self):
        v, w = self.cmd[0], self.turn_gain * self.cmd[1]
        h = self.dt
        self.x += v * h * math.cos(self.th + 0.5 * w * h)
        self.y += v * h * math.sin(self.th + 0.5 * w * h)
        self.th = math.remainder(self.th + w * h, math.tau)
        self.v, self.w, self.k = v, w, self.k + 1

    def odometry(self):
        return OdometrySample(self.k, self.x, self.y, self.th, self.v, self.w)
'''
