// The HDF5 layer under the file readers (src/io/hdf5.hpp): opening files read-only, listing group
// members, reading 1-D and 2-D float64 datasets with their shape and string attributes, each error
// naming the file and the object.
#include <gtest/gtest.h>
#include <hdf5.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "io/hdf5.hpp"
#include "support.hpp"

namespace {

namespace fs = std::filesystem;
namespace h5 = pisco::detail::hdf5;
using pisco_test::expect_error;

void string_attribute(hid_t loc, const char* key, const char* value, bool variable) {
  const hid_t type = H5Tcopy(H5T_C_S1);
  H5Tset_size(type, variable ? H5T_VARIABLE : std::string(value).size());
  const hid_t space = H5Screate(H5S_SCALAR);
  const hid_t attr = H5Acreate2(loc, key, type, space, H5P_DEFAULT, H5P_DEFAULT);
  if (variable) H5Awrite(attr, type, &value);
  else H5Awrite(attr, type, value);
  H5Aclose(attr);
  H5Sclose(space);
  H5Tclose(type);
}

void dataset(hid_t loc, const char* name, hid_t type, std::vector<hsize_t> dims, const std::vector<double>& values) {
  const hid_t space = H5Screate_simple(int(dims.size()), dims.data(), nullptr);
  const hid_t ds = H5Dcreate2(loc, name, type, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  H5Dwrite(ds, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, values.data());
  H5Dclose(ds);
  H5Sclose(space);
}

class Hdf5Layer : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = pisco_test::fresh_test_dir("hdf5");
    file_ = dir_ / "layer.h5";
    // Root: attributes; group "fp" created with tracked link order, members z_table (2-D), a_column
    // (1-D float32), count (integer), sub (a group) and dangling (a soft link to nothing).
    const hid_t f = H5Fcreate(file_.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
    string_attribute(f, "name", "focal plane", true);
    string_attribute(f, "fixed", "telescope", false);
    const double rate = 37.0;
    const hid_t scalar = H5Screate(H5S_SCALAR);
    const hid_t attr = H5Acreate2(f, "rate", H5T_IEEE_F64LE, scalar, H5P_DEFAULT, H5P_DEFAULT);
    H5Awrite(attr, H5T_NATIVE_DOUBLE, &rate);
    H5Aclose(attr);
    H5Sclose(scalar);
    const hid_t gcpl = H5Pcreate(H5P_GROUP_CREATE);
    H5Pset_link_creation_order(gcpl, H5P_CRT_ORDER_TRACKED | H5P_CRT_ORDER_INDEXED);
    const hid_t g = H5Gcreate2(f, "fp", H5P_DEFAULT, gcpl, H5P_DEFAULT);
    dataset(g, "z_table", H5T_IEEE_F64LE, {3, 4}, {0, 1, 2, 3, 10, 11, 12, 13, 20, 21, 22, 23});
    dataset(g, "a_column", H5T_IEEE_F32LE, {3}, {0.5, 1.5, 2.5});
    dataset(g, "count", H5T_STD_I32LE, {3}, {1, 2, 3});
    H5Gclose(H5Gcreate2(g, "sub", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT));
    H5Lcreate_soft("/nowhere", g, "dangling", H5P_DEFAULT, H5P_DEFAULT);
    H5Gclose(g);
    H5Pclose(gcpl);
    H5Fclose(f);
  }
  void TearDown() override {
    EXPECT_EQ(H5Fget_obj_count(H5F_OBJ_ALL, H5F_OBJ_ALL), 0) << "HDF5 objects left open";
    fs::remove_all(dir_);
  }
  fs::path dir_, file_;
};

TEST_F(Hdf5Layer, OpenReadOnlyNamesTheFile) {
  h5::Session session;
  const fs::path missing = dir_ / "missing.h5";
  expect_error([&] { h5::open_read_only(missing); }, missing.string() + ": no such file (expected an HDF5 file)");
  expect_error([&] { h5::open_read_only(dir_); }, dir_.string() + ": is a directory");
  const fs::path text = dir_ / "text.h5";
  std::ofstream(text) << "not HDF5\n";
  expect_error([&] { h5::open_read_only(text); }, text.string() + ": not an HDF5 file");
  EXPECT_TRUE(h5::open_read_only(file_).valid());
}

TEST_F(Hdf5Layer, ListsMembersInCreationOrderAndByKind) {
  h5::Session session;
  const h5::Handle f = h5::open_read_only(file_);
  const std::string where = file_.string();
  EXPECT_EQ(h5::list_members(f.get(), "/fp", where),
            (std::vector<std::string>{"z_table", "a_column", "count", "sub", "dangling"}));
  EXPECT_EQ(h5::list_members(f.get(), "/fp", where, h5::Members::datasets),
            (std::vector<std::string>{"z_table", "a_column", "count"}));
  EXPECT_EQ(h5::list_members(f.get(), "/", where, h5::Members::groups), (std::vector<std::string>{"fp"}));
  EXPECT_TRUE(h5::open_group(f.get(), "/fp/sub", where).valid());
  expect_error([&] { h5::open_group(f.get(), "/fp/nosuch", where); }, where + ": no group '/fp/nosuch'");
  expect_error([&] { h5::open_group(f.get(), "/fp/count", where); }, where + ": '/fp/count' is not a group");
}

TEST_F(Hdf5Layer, ReadsFloat64DatasetsWithTheirShape) {
  h5::Session session;
  const h5::Handle f = h5::open_read_only(file_);
  const std::string where = file_.string();
  const h5::Handle g = h5::open_group(f.get(), "/fp", where);
  const h5::Float64Array table = h5::read_float64_dataset(g.get(), "z_table", "/fp/z_table", 2, where, "a table");
  EXPECT_EQ(table.shape, (std::vector<std::size_t>{3, 4}));
  ASSERT_EQ(table.values.size(), 12u);
  EXPECT_EQ(table.values[1 * 4 + 2], 12.0);
  const h5::Float64Array column = h5::read_float64_dataset(g.get(), "a_column", "/fp/a_column", 1, where, "a column");
  EXPECT_EQ(column.shape, (std::vector<std::size_t>{3}));
  EXPECT_EQ(column.values, (std::vector<double>{0.5, 1.5, 2.5}));
  expect_error([&] { h5::read_float64_dataset(g.get(), "z_table", "/fp/z_table", 1, where, "a column"); },
               where + ": dataset '/fp/z_table' has 2 dimensions (expected a column)");
  expect_error([&] { h5::read_float64_dataset(g.get(), "count", "/fp/count", 1, where, "a column"); },
               "dataset '/fp/count' is not floating point (expected a column)");
  expect_error([&] { h5::read_float64_dataset(g.get(), "nosuch", "/fp/nosuch", 1, where, "a column"); },
               where + ": no dataset '/fp/nosuch' (expected a column)");
  expect_error([&] { h5::read_float64_dataset(g.get(), "sub", "/fp/sub", 1, where, "a column"); },
               "'/fp/sub' is not a dataset");
  expect_error([&] { h5::open_dataset(g.get(), "dangling", "/fp/dangling", where, ""); },
               where + ": cannot open '/fp/dangling'");
}

TEST_F(Hdf5Layer, ReadsStringAttributes) {
  h5::Session session;
  const h5::Handle f = h5::open_read_only(file_);
  const std::string where = file_.string();
  EXPECT_EQ(h5::read_string_attribute(f.get(), "name", "/", where), "focal plane");
  EXPECT_EQ(h5::read_string_attribute(f.get(), "fixed", "/", where), "telescope");
  EXPECT_EQ(h5::read_string_attribute(f.get(), "absent", "/", where), std::nullopt);
  expect_error([&] { h5::read_string_attribute(f.get(), "rate", "/", where); },
               where + ": attribute 'rate' of '/' is not a string");
  EXPECT_EQ(h5::attribute_names(f.get(), where, "the file attributes"),
            (std::vector<std::string>{"fixed", "name", "rate"}));
}

}  // namespace
