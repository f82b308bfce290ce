// Readers of TOD and pointing files (layout: include/pisco/tod_file.hpp; docs/formats.md, "TOD files"
// and "Pointing files").
#include <algorithm>
#include <cstdint>

#include "io/hdf5.hpp"
#include "io/tod_layout.hpp"
#include "pisco/error.hpp"
#include "pisco/tod_file.hpp"

namespace pisco {

namespace fs = std::filesystem;
using namespace detail::hdf5;
namespace tod = detail::tod;

namespace {

// A numeric scalar attribute of a detector group; pisco::Error if it is missing or not numeric.
template <typename T>
T read_numeric_attribute(hid_t group, const char* key, hid_t mem_type, const std::string& where,
                         const std::string& group_name, const char* expected) {
  const std::string what = "attribute " + in_quotes(key) + " of group " + in_quotes("/" + group_name);
  const htri_t exists = H5Aexists(group, key);
  if (exists < 0) fail(where, "cannot look up " + what);
  if (exists == 0) throw Error(where + ": group " + in_quotes("/" + group_name) + " has no attribute " +
                               in_quotes(key) + " (expected " + expected + ")");
  Handle attr = checked(H5Aopen(group, key, H5P_DEFAULT), H5Aclose, where, "cannot open " + what);
  Handle type = checked(H5Aget_type(attr.get()), H5Tclose, where, "cannot get the type of " + what);
  Handle space = checked(H5Aget_space(attr.get()), H5Sclose, where, "cannot get the dataspace of " + what);
  const H5T_class_t cls = H5Tget_class(type.get());
  if ((cls != H5T_FLOAT && cls != H5T_INTEGER) || H5Sget_simple_extent_npoints(space.get()) != 1)
    throw Error(where + ": " + what + " is not a numeric scalar (expected " + expected + ")");
  T value{};
  check(H5Aread(attr.get(), mem_type, &value), where, "cannot read " + what + " (expected " + expected + ")");
  return value;
}

// The groups at the root: the detectors.
std::vector<std::string> root_groups(hid_t file, const std::string& where) {
  return list_members(file, "/", where, Members::groups);
}

std::string list_for_message(const std::vector<std::string>& names) {
  if (names.empty()) return "none";
  std::string s;
  const std::size_t shown = std::min<std::size_t>(names.size(), 10);
  for (std::size_t i = 0; i < shown; ++i) s += (i ? ", " : "") + names[i];
  if (shown < names.size()) s += ", ... (" + std::to_string(names.size()) + " in all)";
  return s;
}

Handle open_detector_group(hid_t file, const std::string& where, const std::string& detector) {
  if (!valid_link_name(detector))
    throw Error(where + ": " + in_quotes(detector) +
                " is not a valid detector name (expected a non-empty group name without '/')");
  if (!has_link(file, detector, where, "group " + in_quotes("/" + detector)))
    throw Error(where + ": no group " + in_quotes("/" + detector) + " for detector " + in_quotes(detector) +
                " (groups in the file: " + list_for_message(root_groups(file, where)) + ")");
  Handle object = checked(H5Oopen(file, detector.c_str(), H5P_DEFAULT), H5Oclose, where,
                          "cannot open " + in_quotes("/" + detector));
  if (H5Iget_type(object.get()) != H5I_GROUP)
    throw Error(where + ": " + in_quotes("/" + detector) + " is not a group (expected one group per detector)");
  return object;
}

// A 1-D floating-point dataset of a detector group.
Dataset open_float_dataset(hid_t group, const std::string& where, const std::string& detector, const char* name,
                           const std::string& expected) {
  const std::string path = "/" + detector + "/" + name;
  if (!has_link(group, name, where, "dataset " + in_quotes(path)))
    throw Error(where + ": group " + in_quotes("/" + detector) + " has no dataset " + in_quotes(name) + " (expected " +
                expected + ")");
  Dataset ds = open_dataset(group, name, path, where, expected);
  require_float(ds, 1, where, expected);
  return ds;
}

}  // namespace

std::vector<TodFileDetector> read_tod_detectors(const fs::path& file) {
  Session session;
  const std::string where = file.string();
  Handle h = open_read_only(file);
  std::vector<TodFileDetector> out;
  for (const std::string& name : root_groups(h.get(), where)) {
    Handle group = checked(H5Gopen2(h.get(), name.c_str(), H5P_DEFAULT), H5Gclose, where,
                           "cannot open group " + in_quotes("/" + name));
    TodFileDetector d;
    d.name = name;
    d.zeta = read_numeric_attribute<double>(group.get(), "zeta", H5T_NATIVE_DOUBLE, where, name, "a float64 in rad");
    d.epsilon = read_numeric_attribute<double>(group.get(), "epsilon", H5T_NATIVE_DOUBLE, where, name, "a float64");
    d.gain = read_numeric_attribute<double>(group.get(), "gain", H5T_NATIVE_DOUBLE, where, name, "a float64");
    d.beam = static_cast<std::size_t>(read_numeric_attribute<std::uint64_t>(
        group.get(), "beam", H5T_NATIVE_UINT64, where, name, "an unsigned integer beam index"));
    out.push_back(std::move(d));
  }
  return out;
}

std::vector<double> read_tod_signal(const fs::path& file, const std::string& detector) {
  Session session;
  const std::string where = file.string();
  Handle h = open_read_only(file);
  Handle group = open_detector_group(h.get(), where, detector);
  const Dataset ds =
      open_float_dataset(group.get(), where, detector, "signal", "a 1-D float64 or float32 dataset 'signal'");
  return read_float64(ds, where);
}

std::vector<Quat> read_tod_quats(const fs::path& file, const std::string& detector) {
  Session session;
  const std::string where = file.string();
  Handle h = open_read_only(file);
  Handle group = open_detector_group(h.get(), where, detector);
  const std::string expected = "a float64 dataset 'quat' of shape (samples, 4), written with tod_pointing";
  const Float64Array a = read_float64_dataset(group.get(), tod::quat_name, "/" + detector + "/" + tod::quat_name, 2,
                                              where, expected);
  if (a.shape[1] != 4)
    throw Error(where + ": dataset " + in_quotes("/" + detector + "/" + tod::quat_name) + " has " +
                std::to_string(a.shape[1]) + " columns (expected " + expected + ")");
  std::vector<Quat> out(a.shape[0]);
  for (std::size_t i = 0; i < out.size(); ++i) out[i] = {a.values[4 * i], a.values[4 * i + 1], a.values[4 * i + 2], a.values[4 * i + 3]};
  return out;
}

std::vector<double> read_tod_weights(const fs::path& file, const std::string& detector) {
  Session session;
  const std::string where = file.string();
  Handle h = open_read_only(file);
  Handle group = open_detector_group(h.get(), where, detector);
  const std::string expected = "a float64 dataset 'weights' of shape (samples, 3), written with tod_weights";
  const Float64Array a = read_float64_dataset(group.get(), tod::weights_name, "/" + detector + "/" + tod::weights_name,
                                              2, where, expected);
  if (a.shape[1] != 3)
    throw Error(where + ": dataset " + in_quotes("/" + detector + "/" + tod::weights_name) + " has " +
                std::to_string(a.shape[1]) + " columns (expected " + expected + ")");
  return a.values;
}

std::vector<std::uint8_t> read_tod_flags(const fs::path& file, const std::string& detector) {
  Session session;
  const std::string where = file.string();
  Handle h = open_read_only(file);
  Handle group = open_detector_group(h.get(), where, detector);
  const std::string path = "/" + detector + "/" + tod::flags_name;
  if (!has_link(group.get(), tod::flags_name, where, "dataset " + in_quotes(path))) return {};
  const std::string expected = "a one-dimensional integer dataset 'flags', one value per sample";
  Dataset d = open_dataset(group.get(), tod::flags_name, path, where, expected);
  if (d.type_class != H5T_INTEGER || d.shape.size() != 1)
    throw Error(where + ": dataset " + in_quotes(path) + " is not one-dimensional integers (expected " + expected + ")");
  std::vector<std::uint8_t> out(d.elements());
  if (!out.empty())
    check(H5Dread(d.handle.get(), H5T_NATIVE_UINT8, H5S_ALL, H5S_ALL, H5P_DEFAULT, out.data()), where,
          "cannot read dataset " + in_quotes(path));
  return out;
}

std::map<std::string, std::string> read_tod_attributes(const fs::path& file) {
  Session session;
  const std::string where = file.string();
  Handle h = open_read_only(file);
  Handle root = checked(H5Gopen2(h.get(), "/", H5P_DEFAULT), H5Gclose, where, "cannot open the root group");
  std::map<std::string, std::string> out;
  for (const std::string& name : attribute_names(root.get(), where, "the file attributes")) {
    const std::string what = "file attribute " + in_quotes(name);
    Handle attr = checked(H5Aopen(root.get(), name.c_str(), H5P_DEFAULT), H5Aclose, where, "cannot open " + what);
    std::string value;
    if (attribute_as_text(attr.get(), value, where, what)) out.emplace(name, std::move(value));
  }
  return out;
}

Pointing read_pointing_hdf5(const fs::path& file, const std::string& detector) {
  Session session;
  const std::string where = file.string();
  Handle h = open_read_only(file);
  Handle group = open_detector_group(h.get(), where, detector);
  const std::string expected = "1-D float64 or float32 datasets theta, phi and psi of equal length, in rad";
  Dataset ds[3];
  for (int k = 0; k < 3; ++k)
    ds[k] = open_float_dataset(group.get(), where, detector, tod::pointing_names[k], expected);
  const std::string origin = where + ":/" + detector;
  if (ds[1].shape[0] != ds[0].shape[0] || ds[2].shape[0] != ds[0].shape[0])
    throw Error(origin + ": datasets theta, phi and psi have different lengths (" + std::to_string(ds[0].shape[0]) +
                ", " + std::to_string(ds[1].shape[0]) + ", " + std::to_string(ds[2].shape[0]) +
                "; expected equal lengths)");
  Pointing p;
  p.theta = read_float64(ds[0], where);
  p.phi = read_float64(ds[1], where);
  p.psi = read_float64(ds[2], where);
  check_pointing(p.view(), origin.c_str());
  return p;
}

std::vector<std::string> pointing_detectors(const fs::path& file) {
  Session session;
  const std::string where = file.string();
  Handle h = open_read_only(file);
  return root_groups(h.get(), where);
}

}  // namespace pisco
