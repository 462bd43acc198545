#include <vendor/clock.h>
namespace fixture {
double vendorSeconds() { return vendor::seconds(); }
}
