// Several performers in one `tetrig run` (tools/run.hpp): the --performer text, the stage file,
// the checks that a stage can run. Load time only (allocates, throws one clear line).
#include "run.hpp"

#include "tetrig/printable_text.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

namespace tetrig::tools {

namespace {

int parseCpu(const std::string& value, const std::string& where) {
  std::size_t used = 0;
  int cpu = -1;
  try {
    cpu = std::stoi(value, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used != value.size() || value.empty() || cpu < 0 || cpu > 4095)
    throw std::invalid_argument(where + ": cpu must be a CPU number 0..4095, not '" + printableText(value, 32) + "'");
  return cpu;
}

// A playback source's file, relative to the stage file's folder ("c3d:take.c3d" -> "c3d:/stage/take.c3d").
std::string resolveSource(const std::string& source, const std::filesystem::path& base) {
  for (const char* kind : {"c3d:", "replay:"}) {
    const std::string k = kind;
    if (source.rfind(k, 0) == 0) {
      const std::filesystem::path file = source.substr(k.size());
      return k + (file.is_absolute() ? file : base / file).string();
    }
  }
  return source;
}

std::string resolvePath(const std::string& path, const std::filesystem::path& base) {
  if (path.empty()) return path;
  const std::filesystem::path p = path;
  return (p.is_absolute() ? p : base / p).string();
}

// One text key of a performer, the same in both forms but for the coarse rig's spelling
// (`coarse_key`); paths relative to `base` (empty: as given). False for a key it does not know.
bool setTextKey(PerformerSpec& spec, const std::string& key, const std::string& value, const std::filesystem::path& base,
                const char* coarse_key) {
  if (key == "rig") spec.rig_path = resolvePath(value, base);
  else if (key == coarse_key) spec.coarse_rig_path = resolvePath(value, base);
  else if (key == "source") spec.source = resolveSource(value, base);
  else if (key == "publish") spec.publish = value;
  else if (key == "subject") spec.subject = value;
  else if (key == "name") spec.name = value;
  else return false;
  return true;
}

}  // namespace

PerformerSpec parsePerformerSpec(const std::string& text) {
  PerformerSpec spec;
  const std::string where = "--performer '" + printableText(text, 200) + "'";
  std::set<std::string> seen;
  std::size_t at = 0;
  while (at <= text.size()) {
    const std::size_t comma = text.find(',', at);
    const std::string item = text.substr(at, comma == std::string::npos ? std::string::npos : comma - at);
    at = comma == std::string::npos ? text.size() + 1 : comma + 1;
    const std::size_t eq = item.find('=');
    if (eq == std::string::npos || eq == 0)
      throw std::invalid_argument(where + ": '" + printableText(item, 64) + "' is not KEY=VALUE (keys: rig, source, publish, subject, name, coarse-rig, cpu)");
    const std::string key = item.substr(0, eq), value = item.substr(eq + 1);
    if (!seen.insert(key).second) throw std::invalid_argument(where + ": " + printableText(key, 32) + " given twice");
    if (key == "cpu") spec.cpu = parseCpu(value, where);
    else if (!setTextKey(spec, key, value, {}, "coarse-rig")) throw std::invalid_argument(where + ": unknown key '" + printableText(key, 32) + "' (keys: rig, source, publish, subject, name, coarse-rig, cpu)");
  }
  return spec;
}

std::vector<PerformerSpec> loadStageFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error("cannot read the stage file " + path);
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(in);
  } catch (const nlohmann::json::parse_error& e) {
    throw std::runtime_error("stage file " + path + " is not valid JSON: " + e.what());
  }
  if (!j.is_object() || !j.contains("performers") || !j["performers"].is_array())
    throw std::runtime_error("stage file " + path + ": expected {\"performers\": [{\"rig\": ..., \"source\": ..., \"publish\": ...}, ...]}");
  for (const auto& [key, value] : j.items())
    if (key != "performers") throw std::runtime_error("stage file " + path + ": unknown key '" + printableText(key, 64) + "' (only \"performers\")");
  const std::filesystem::path base = std::filesystem::path(path).parent_path();
  std::vector<PerformerSpec> out;
  std::size_t index = 0;
  for (const nlohmann::json& p : j["performers"]) {
    const std::string where = "stage file " + path + ", performer " + std::to_string(index++);
    if (!p.is_object()) throw std::runtime_error(where + ": expected an object");
    PerformerSpec spec;
    for (const auto& [key, value] : p.items()) {
      if (key == "cpu") {
        if (!value.is_number_integer()) throw std::runtime_error(where + ": cpu must be an integer");
        spec.cpu = parseCpu(std::to_string(value.get<long long>()), where);
        continue;
      }
      if (!value.is_string()) throw std::runtime_error(where + ": " + printableText(key, 64) + " must be a string");
      if (!setTextKey(spec, key, value.get<std::string>(), base, "coarse_rig"))
        throw std::runtime_error(where + ": unknown key '" + printableText(key, 64) + "' (keys: rig, source, publish, subject, name, coarse_rig, cpu)");
    }
    out.push_back(std::move(spec));
  }
  return out;
}

void checkStage(std::vector<PerformerSpec>& performers) {
  if (performers.empty()) throw std::invalid_argument("the stage has no performer");
  std::set<std::string> segments, names;
  for (std::size_t i = 0; i < performers.size(); ++i) {
    PerformerSpec& p = performers[i];
    const std::string where = "performer " + std::to_string(i + 1) + (p.name.empty() ? "" : " (" + printableText(p.name, 64) + ")");
    if (p.rig_path.empty()) throw std::invalid_argument(where + " has no rig (rig=PATH)");
    if (p.source.empty()) throw std::invalid_argument(where + " has no source (source=SPEC, e.g. c3d:take.c3d)");
    if (p.publish.empty()) throw std::invalid_argument(where + " has no segment (publish=NAME)");
    if (p.name.empty()) p.name = p.subject.empty() ? p.publish : p.subject;
    const std::string segment = p.publish.front() == '/' ? p.publish.substr(1) : p.publish;
    if (!segments.insert(segment).second)
      throw std::invalid_argument(where + " publishes to segment '" + printableText(p.publish, 64) + "', which another performer already uses");
    if (!names.insert(p.name).second) throw std::invalid_argument(where + ": another performer has the name '" + printableText(p.name, 64) + "'");
  }
}

}  // namespace tetrig::tools
