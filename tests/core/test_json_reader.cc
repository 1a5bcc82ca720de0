#include <gtest/gtest.h>

#include <fstream>
#include <random>

#include "core/camera.h"
#include "core/error.h"
#include "core/json_reader.h"
#include "core/opencv_yaml.h"
#include "test_util.h"

namespace arreg {
namespace {

using nlohmann::json;

// Returns the arreg::Error message thrown by `f` ("" and a failure if none).
template <typename F>
std::string ErrorMessage(F f) {
  try {
    f();
  } catch (const Error& e) {
    return e.what();
  }
  ADD_FAILURE() << "no arreg::Error thrown";
  return "";
}

TEST(JsonObjectReader, ReadsTypedValuesAndKeepsDefaults) {
  const json j = json::parse(R"({"fx": 500.5, "n": 3, "on": true, "name": "liver",
      "v3": [1, 2, 3], "list": [0.5, 1.5], "m": [[1,2,3],[4,5,6],[7,8,9]], "flat": [1,0,0,0,1,0,0,0,1],
      "whole": 4.0, "nothing": null})");
  JsonObjectReader r(j, "s.json", "scene.x");
  double fx = 0;
  int n = 0;
  bool on = false;
  std::string name;
  Eigen::Vector3d v3;
  std::vector<double> list;
  Eigen::Matrix3d m, flat;
  int whole = 0;
  double k1 = 0.25;
  double nothing = 7.0;
  r.Required("fx", &fx);
  r.Required("n", &n);
  r.Required("on", &on);
  r.Required("name", &name);
  r.Required("v3", &v3);
  r.Required("list", &list);
  r.Required("m", &m);
  r.Required("flat", &flat);
  r.Required("whole", &whole);
  EXPECT_FALSE(r.Optional("k1", &k1));
  EXPECT_FALSE(r.Optional("nothing", &nothing));  // null counts as absent
  EXPECT_NO_THROW(r.Finish());
  EXPECT_EQ(fx, 500.5);
  EXPECT_EQ(n, 3);
  EXPECT_TRUE(on);
  EXPECT_EQ(name, "liver");
  EXPECT_EQ(v3, Eigen::Vector3d(1, 2, 3));
  EXPECT_EQ(list.size(), 2u);
  EXPECT_EQ(m(1, 2), 6.0);
  EXPECT_EQ(m(2, 0), 7.0);
  EXPECT_TRUE(flat.isIdentity());
  EXPECT_EQ(whole, 4);
  EXPECT_EQ(k1, 0.25);
  EXPECT_EQ(nothing, 7.0);
  EXPECT_EQ(r.Get("absent", 9), 9);
}

TEST(JsonObjectReader, UnknownKeysAreNamedWithTheExpectedOnes) {
  const json j = json::parse(R"({"fx": 1, "fxx": 2, "zz": 3})");
  JsonObjectReader r(j, "scene.json", "scene.camera");
  double fx = 0, fy = 0;
  r.Required("fx", &fx);
  r.Optional("fy", &fy);
  const std::string msg = ErrorMessage([&] { r.Finish(); });
  EXPECT_NE(msg.find("scene.json: scene.camera.fxx, scene.camera.zz: unknown keys"),
            std::string::npos)
      << msg;
  EXPECT_NE(msg.find("expected one of: fx, fy"), std::string::npos) << msg;
}

TEST(JsonObjectReader, MissingAndWrongTypesNameTheKeyPath) {
  const json j = json::parse(R"({"a": "x", "b": 2.5, "c": [1, "two", 3], "d": {"e": true},
                                 "big": 1e20, "neg": -3})");
  JsonObjectReader r(j, "f.json", "root");
  double d = 0;
  int i = 0;
  std::vector<double> v;
  EXPECT_NE(ErrorMessage([&] {
              r.Required("missing", &d);
            }).find("f.json: root.missing: required key is missing"),
            std::string::npos);
  EXPECT_NE(
      ErrorMessage([&] { r.Required("a", &d); }).find("root.a: expected a number, got string"),
      std::string::npos);
  EXPECT_NE(ErrorMessage([&] { r.Required("b", &i); }).find("root.b: expected an integer"),
            std::string::npos);
  EXPECT_NE(ErrorMessage([&] { r.Required("c", &v); }).find("root.c[1]: expected a number"),
            std::string::npos);
  EXPECT_NE(ErrorMessage([&] { r.Required("big", &i); }).find("does not fit"), std::string::npos);
  JsonObjectReader child = r.Object("d");
  EXPECT_EQ(child.path(), "root.d");
  double e = 0;
  EXPECT_NE(ErrorMessage([&] {
              child.Required("e", &e);
            }).find("root.d.e: expected a number, got boolean"),
            std::string::npos);
  EXPECT_NE(ErrorMessage([&] { r.Object("a"); }).find("root.a: expected a JSON object"),
            std::string::npos);
}

TEST(JsonObjectReader, RangeChecksAndChoices) {
  const json j = json::parse(R"({"mode": "cg", "bad": "lu", "nu": 0.5})");
  JsonObjectReader r(j, "f.json", "mechanics");
  std::string mode, bad;
  r.RequiredChoice("mode", {"cg", "cholmod"}, &mode);
  EXPECT_EQ(mode, "cg");
  const std::string msg = ErrorMessage([&] { r.RequiredChoice("bad", {"cg", "cholmod"}, &bad); });
  EXPECT_NE(msg.find("mechanics.bad: \"lu\" is not one of \"cg\", \"cholmod\""), std::string::npos)
      << msg;
  EXPECT_NO_THROW(r.CheckPositive("x", 1e-9));
  EXPECT_NE(ErrorMessage([&] {
              r.CheckPositive("x", 0.0);
            }).find("mechanics.x: must be a positive number"),
            std::string::npos);
  EXPECT_NE(ErrorMessage([&] { r.CheckNonNegative("x", -1.0); }).find("mechanics.x"),
            std::string::npos);
  EXPECT_NO_THROW(r.CheckInRange("nu", 0.5, 0.0, 0.5));
  EXPECT_NE(ErrorMessage([&] {
              r.CheckInRange("nu", 0.5, -1.0, 0.5, true);
            }).find("must be in (-1, 0.5)"),
            std::string::npos);
}

TEST(JsonObjectReader, ObjectArraysCarryIndices) {
  const json j = json::parse(R"({"items": [{"name": "a"}, {"name": "b", "extra": 1}]})");
  JsonObjectReader r(j, "f.json", "");
  std::vector<JsonObjectReader> items = r.ObjectArray("items", true);
  ASSERT_EQ(items.size(), 2u);
  std::string name;
  items[0].Required("name", &name);
  EXPECT_NO_THROW(items[0].Finish());
  items[1].Required("name", &name);
  EXPECT_NE(ErrorMessage([&] { items[1].Finish(); }).find("items[1].extra: unknown key"),
            std::string::npos);
  EXPECT_TRUE(r.ObjectArray("absent").empty());
  EXPECT_NE(ErrorMessage([&] {
              r.ObjectArray("absent2", true);
            }).find("absent2: required key is missing"),
            std::string::npos);
}

TEST(ParseJson, SyntaxErrorsGiveLineAndColumn) {
  const std::string text = "{\n  \"a\": 1,\n  \"b\": [1, 2,, 3]\n}\n";
  const std::string msg = ErrorMessage([&] { ParseJsonText(text, "x.json"); });
  EXPECT_NE(msg.find("x.json: line 3, column 14"), std::string::npos) << msg;
  EXPECT_EQ(msg.find("[json.exception"), std::string::npos) << msg;
}

TEST(ParseJson, NumberOverflowIsAnArregError) {
  const std::string msg = ErrorMessage([] { ParseJsonText(R"({"fx": 1e999})", "o.json"); });
  EXPECT_NE(msg.find("o.json"), std::string::npos) << msg;
  EXPECT_NE(msg.find("1e999"), std::string::npos) << msg;
}

TEST(ParseJson, DuplicateKeysAreErrors) {
  const std::string msg = ErrorMessage([] {
    ParseJsonText(R"({"camera": {"fx": 1, "fy": 2}, "list": [{"a": 1}, {"a": 2, "a": 3}]})",
                  "d.json");
  });
  EXPECT_NE(msg.find("d.json: list[1].a: duplicate key"), std::string::npos) << msg;
  const std::string msg2 =
      ErrorMessage([] { ParseJsonText(R"({"camera": {"fx": 1, "fx": 2}})", "d.json"); });
  EXPECT_NE(msg2.find("camera.fx: duplicate key"), std::string::npos) << msg2;
}

TEST(ParseJson, CommentsAreAcceptedAndMissingFilesNamed) {
  const json j = ParseJsonText("{\n // the focal length\n \"fx\": 2 /* px */\n}", "c.json");
  EXPECT_EQ(j["fx"], 2);
  const std::string missing = testing::ScratchDir("json_missing") + "/nope.json";
  EXPECT_NE(ErrorMessage([&] { ParseJsonFile(missing); }).find("nope.json"), std::string::npos);
}

// ----- the OpenCV YAML subset -----

TEST(OpenCvYaml, ParsesNestedMappingsSequencesAndScalars) {
  const YamlNode root = ParseOpenCvYaml(R"(%YAML:1.0
---
name: "a # not a comment"   # a comment
quote: 'it''s'
nested:
  inner: 3
  deeper:
    x: [1, 2,
        3]
  list:
    - 1.5
    - two
  people:
    - name: ann
      age: 40
    - name: bob
      age: 41
flow_map: {rows: 2, cols: 1, data: [ 4., 5. ]}
empty:
after: .5
...
ignored: after the document end
)",
                                        "t.yaml");
  ASSERT_EQ(root.kind, YamlNode::Kind::kMapping);
  EXPECT_EQ(root.Find("name")->scalar, "a # not a comment");
  EXPECT_EQ(root.Find("quote")->scalar, "it's");
  const YamlNode* nested = root.Find("nested");
  ASSERT_NE(nested, nullptr);
  EXPECT_EQ(YamlToInt(*nested->Find("inner"), "t.yaml", "inner"), 3);
  const YamlNode* x = nested->Find("deeper")->Find("x");
  ASSERT_EQ(x->items.size(), 3u);
  EXPECT_EQ(x->line, 8);
  const YamlNode* list = nested->Find("list");
  ASSERT_EQ(list->items.size(), 2u);
  EXPECT_EQ(list->items[1].scalar, "two");
  const YamlNode* people = nested->Find("people");
  ASSERT_EQ(people->items.size(), 2u);
  EXPECT_EQ(people->items[1].Find("name")->scalar, "bob");
  EXPECT_EQ(people->items[1].Find("age")->scalar, "41");
  const Eigen::MatrixXd m = YamlToMatrix(*root.Find("flow_map"), "t.yaml", "flow_map");
  ASSERT_EQ(m.rows(), 2);
  EXPECT_EQ(m(1, 0), 5.0);
  EXPECT_EQ(root.Find("empty")->kind, YamlNode::Kind::kNull);
  EXPECT_EQ(YamlToDouble(*root.Find("after"), "t.yaml", "after"), 0.5);
  EXPECT_EQ(root.Find("ignored"), nullptr);
}

TEST(OpenCvYaml, ByteOrderMarkAndCrLfAreAccepted) {
  const YamlNode root =
      ParseOpenCvYaml("\xEF\xBB\xBF%YAML:1.0\r\n---\r\na: 1\r\nb: [2,\r\n 3]\r\n", "w.yaml");
  EXPECT_EQ(root.Find("a")->scalar, "1");
  EXPECT_EQ(YamlToMatrix(*root.Find("b"), "w.yaml", "b")(1, 0), 3.0);
  EXPECT_EQ(root.Find("b")->line, 4);
}

TEST(OpenCvYaml, ErrorsNameTheLine) {
  EXPECT_NE(ErrorMessage([] {
              ParseOpenCvYaml("a: 1\nb 2\n", "e.yaml");
            }).find("e.yaml: line 2: expected 'key: value'"),
            std::string::npos);
  EXPECT_NE(ErrorMessage([] {
              ParseOpenCvYaml("a: 1\na: 2\n", "e.yaml");
            }).find("line 2: duplicate key 'a'"),
            std::string::npos);
  EXPECT_NE(ErrorMessage([] { ParseOpenCvYaml("a:\n\tb: 1\n", "e.yaml"); }).find("line 2: tab"),
            std::string::npos);
  EXPECT_NE(ErrorMessage([] {
              ParseOpenCvYaml("a: [1, 2\nb: 3\n", "e.yaml");
            }).find("line 1: unterminated"),
            std::string::npos);
  EXPECT_NE(ErrorMessage([] {
              ParseOpenCvYaml("a: [1,\n 2} ]\n", "e.yaml");
            }).find("line 2: expected ','"),
            std::string::npos);
  EXPECT_NE(ErrorMessage([] {
              ParseOpenCvYaml("a: \"open\nb: 1\n", "e.yaml");
            }).find("line 1: unterminated quoted"),
            std::string::npos);
  EXPECT_NE(ErrorMessage([] { ParseOpenCvYaml("a: |\n  text\n", "e.yaml"); }).find("block scalars"),
            std::string::npos);
  const YamlNode root = ParseOpenCvYaml(
      "m: !!opencv-matrix\n  rows: 2\n  cols: 2\n  dt: d\n  data: [1, 2, 3]\n", "e.yaml");
  EXPECT_EQ(root.Find("m")->tag, "opencv-matrix");
  EXPECT_NE(ErrorMessage([&] {
              YamlToMatrix(*root.Find("m"), "e.yaml", "m");
            }).find("e.yaml: line 5: m.data: has 3 numbers"),
            std::string::npos);
}

// Truncated or corrupted calibration files must give arreg::Error (or parse),
// never another exception type or a crash (the sanitizer build checks memory).
TEST(OpenCvYaml, CorruptedInputOnlyEverThrowsArregError) {
  const std::string good = R"(%YAML:1.0
---
image_width: 640
image_height: 480
camera_matrix: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 535.9, 0., 342.3, 0.,
       535.9, 235.6, 0., 0., 1. ]
distortion_coefficients: {rows: 5, cols: 1, dt: d, data: [ -0.27, -0.04, 0.0018, -0.0003, 0.24 ]}
people:
  - name: 'a''b'
    age: "4"
)";
  EXPECT_NO_THROW(ReadCameraOpenCvYaml(good, "good.yaml"));
  std::mt19937 rng(1);
  const std::string alphabet = " :-[]{},'\"#!\n\t0a.";
  int errors = 0, parsed = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    std::string text = good;
    if (trial < static_cast<int>(good.size())) {
      text = good.substr(0, trial);
    } else {
      const int edits = 1 + static_cast<int>(rng() % 4);
      for (int e = 0; e < edits; ++e) text[rng() % text.size()] = alphabet[rng() % alphabet.size()];
    }
    try {
      ReadCameraOpenCvYaml(text, "fuzz.yaml");
      ++parsed;
    } catch (const Error&) {
      ++errors;
    } catch (const std::exception& e) {
      ADD_FAILURE() << "non-arreg exception " << e.what() << " for:\n" << text;
    }
  }
  EXPECT_GT(errors, 0);
  EXPECT_GT(parsed, 0);
}

TEST(ParseJson, CorruptedCameraJsonOnlyEverThrowsArregError) {
  const std::string good =
      R"({"width": 640, "height": 480, "fx": 500, "fy": 500, "cx": 319.5, "cy": 239.5,
          "distortion": [-0.1, 0.01, 0, 0, 0],
          "camera_from_world": {"rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "translation_mm": [0, 0, 0]}})";
  std::mt19937 rng(2);
  const std::string alphabet = " :[]{},\"0-.e";
  for (int trial = 0; trial < 2000; ++trial) {
    std::string text = trial < static_cast<int>(good.size()) ? good.substr(0, trial) : good;
    if (trial >= static_cast<int>(good.size()))
      text[rng() % text.size()] = alphabet[rng() % alphabet.size()];
    try {
      const nlohmann::json j = ParseJsonText(text, "fuzz.json");
      JsonObjectReader r(j, "fuzz.json", "");
      ReadCameraJson(r);
    } catch (const Error&) {
    } catch (const std::exception& e) {
      ADD_FAILURE() << "non-arreg exception " << e.what() << " for:\n" << text;
    }
  }
}

enum class Fruit { kApple, kPear, kFig };
constexpr EnumName<Fruit> kFruitNames[] = {
    {Fruit::kApple, "apple"}, {Fruit::kPear, "pear"}, {Fruit::kFig, "fig"}};

TEST(EnumNames, NamesAndValuesRoundTripAndOthersAreErrorsListingTheNames) {
  for (const EnumName<Fruit>& e : kFruitNames) {
    EXPECT_STREQ(NameOf(kFruitNames, e.value), e.name);
    EXPECT_EQ(FindName(kFruitNames, e.name), e.value);
  }
  EXPECT_STREQ(NameOf(kFruitNames, static_cast<Fruit>(7)), "?");
  EXPECT_FALSE(FindName(kFruitNames, "Apple").has_value());  // names are exact
  EXPECT_EQ(NameList(kFruitNames), "apple, pear or fig");
  EXPECT_EQ(ErrorMessage([] { ParseName(kFruitNames, "plum", "f.json", "fruit"); }),
            "f.json: fruit: must be apple, pear or fig, got 'plum'");
}

TEST(JsonObjectReader, EnumMembersAreReadByTheirTable) {
  const json j = json::parse(R"({"a": "pear", "b": "plum"})");
  JsonObjectReader r(j, "f.json", "basket");
  Fruit fruit = Fruit::kApple;
  r.RequiredEnum("a", kFruitNames, &fruit);
  EXPECT_EQ(fruit, Fruit::kPear);
  EXPECT_FALSE(r.OptionalEnum("c", kFruitNames, &fruit));
  EXPECT_EQ(fruit, Fruit::kPear);
  EXPECT_EQ(ErrorMessage([&] { r.OptionalEnum("b", kFruitNames, &fruit); }),
            "f.json: basket.b: \"plum\" is not one of \"apple\", \"pear\", \"fig\"");
  EXPECT_NE(ErrorMessage([&] { r.RequiredEnum("c", kFruitNames, &fruit); }).find("basket.c"),
            std::string::npos);
}

}  // namespace
}  // namespace arreg
