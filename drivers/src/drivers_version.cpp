// Keeps tetrig_drivers a valid library while its source lists are filled in.
namespace tetrig::drivers {
const char* version() { return "0.1.0"; }
}  // namespace tetrig::drivers
