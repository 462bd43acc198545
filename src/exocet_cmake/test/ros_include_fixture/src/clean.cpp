#include "fixture/clean.h"
namespace fixture {
double halve(double value) { return value / 2; }
}
