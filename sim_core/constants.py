"""Physical constants (SI, CODATA 2018 exact values where defined)."""

SPEED_OF_LIGHT_M_S = 299_792_458.0
PLANCK_J_S = 6.626_070_15e-34
BOLTZMANN_J_K = 1.380_649e-23

#: one "sun" as the solar-simulator industry defines it (AM1.5G, IEC 60904-9) [W/m^2]
ONE_SUN_W_M2 = 1000.0
#: mean Sun-Earth distance [m]
ASTRONOMICAL_UNIT_M = 1.495_978_707e11
#: solar radius used by the seed paper (eq. 12) [m]
SOLAR_RADIUS_M = 6.5955e8
#: solar radiation temperature used by the seed paper (eq. 12) [K]
SOLAR_TEMPERATURE_K = 5900.0
EARTH_RADIUS_M = 6.370e6
EARTH_ALBEDO = 0.35
MOON_RADIUS_M = 1.738e6
MOON_ALBEDO = 0.12
