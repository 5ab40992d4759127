"""Diagnostic only: iSAM2 replaced by GTSAM's IncrementalFixedLagSmoother (lag LAG s by keyframe
number at 10 Hz), the full-graph estimate kept as variables leave the window. Not committed."""
import gtsam

LAG = 10.0
_ISAM2 = gtsam.ISAM2


class FixedLag:
    def __init__(self, params):
        self._p = params
        self.s = gtsam.IncrementalFixedLagSmoother(LAG, params)
        self.all = gtsam.Values()

    def params(self):
        return self._p

    def update(self, graph=None, values=None):
        if graph is None:
            return
        ts = {int(k): gtsam.Symbol(k).index() * 0.1 for k in values.keys()}
        self.s.update(graph, values, ts)
        est = self.s.calculateEstimate()
        self.all.insert_or_assign(est)  # the window only: O(lag)

    def calculateEstimate(self):
        return self.all

    def calculateEstimatePose3(self, k):
        return self.s.calculateEstimatePose3(k)

    def calculateEstimateVector(self, k):
        return self.s.calculateEstimateVector(k)

    def calculateEstimateConstantBias(self, k):
        return self.s.calculateEstimateConstantBias(k)


def install():
    gtsam.ISAM2 = FixedLag
