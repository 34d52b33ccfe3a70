"""The component library: sources, sensors and noise, the wheel pendulum's sensor chain, the
estimator and controller components, a plant model stepped in Python, and a conversion on a
connection. Each registers its ``kind`` for scenario files (:data:`cosim.core.component.COMPONENTS`)."""
from .control import LQRController, lqr_gain
from .conversion import Conversion
from .estimation import EstimatorComponent
from .imu import Accelerometer, Encoder, Gyroscope, TiltFusion
from .noise import CounterNoise, PerInstantNoise, counter_normal, make_noise
from .plant_model import ModelComponent
from .sensors import ProcessNoise, Sensor
from .sources import PRBS, Constant, Sine, Step, Table, prbs_bits

__all__ = ["PRBS", "Accelerometer", "Constant", "Conversion", "CounterNoise", "Encoder", "EstimatorComponent",
           "Gyroscope", "LQRController", "ModelComponent", "PerInstantNoise", "ProcessNoise", "Sensor", "Sine", "Step",
           "Table", "TiltFusion", "counter_normal", "lqr_gain", "make_noise", "prbs_bits"]
