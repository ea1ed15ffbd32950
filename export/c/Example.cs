// A C# program over the C runtime (Unity, Godot and .NET call it the same way): step a model
// file from rest under gravity and print the lowest vertex height per step.
//
//   cc -std=c99 -O2 -shared -fPIC -o libanisofem.so \
//      arrays.c linalg.c reduced.c framed.c model.c files.c -lm
//   mcs Example.cs && mono Example.exe tentacle 100 0.02      (or: dotnet run)
using System;
using System.Globalization;
using System.Runtime.InteropServices;

static class Anisofem {
    const string Lib = "anisofem";   // libanisofem.so, anisofem.dll, libanisofem.dylib
    [DllImport(Lib)]
    public static extern IntPtr af_load(string path, string angle, byte[] error, UIntPtr size);
    [DllImport(Lib)] public static extern void af_free(IntPtr m);
    [DllImport(Lib)] public static extern int af_vertices(IntPtr m);
    [DllImport(Lib)] public static extern int af_state_size(IntPtr m);
    [DllImport(Lib)] public static extern void af_rest_state(IntPtr m, double[] state);
    [DllImport(Lib)] public static extern IntPtr af_masses(IntPtr m);
    [DllImport(Lib)] public static extern int af_gravity(IntPtr m, double[] g);
    [DllImport(Lib)] public static extern int af_set_constant_force(IntPtr m, double[] force);
    [DllImport(Lib)]
    public static extern int af_step(IntPtr m, double[] state, double[] force, double[] bases,
                                     double dt);
    [DllImport(Lib)] public static extern IntPtr af_error(IntPtr m);
    [DllImport(Lib)] public static extern void af_positions(IntPtr m, double[] state, double[] x);
}

static class Example {
    static int Main(string[] args) {
        if (args.Length != 3) { Console.Error.WriteLine("usage: Example PATH STEPS DT"); return 2; }
        var error = new byte[512];
        IntPtr m = Anisofem.af_load(args[0], null, error, (UIntPtr)error.Length);
        if (m == IntPtr.Zero) {
            Console.Error.WriteLine(System.Text.Encoding.UTF8.GetString(error).TrimEnd('\0'));
            return 1;
        }
        int n = Anisofem.af_vertices(m), steps = int.Parse(args[1]);
        double dt = double.Parse(args[2], CultureInfo.InvariantCulture);
        double[] g = {0.0, 0.0, -9.81}, mass = new double[n], gravity = new double[3 * n];
        double[] state = new double[Anisofem.af_state_size(m)], x = new double[3 * n];
        Anisofem.af_gravity(m, g);
        Marshal.Copy(Anisofem.af_masses(m), mass, 0, n);
        for (int i = 0; i < 3 * n; i++) gravity[i] = mass[i / 3] * g[i % 3];
        Anisofem.af_rest_state(m, state);
        Anisofem.af_set_constant_force(m, gravity);
        for (int k = 0; k < steps; k++) {
            if (Anisofem.af_step(m, state, null, null, dt) != 0) {
                string why = Marshal.PtrToStringAnsi(Anisofem.af_error(m));
                Console.Error.WriteLine($"step {k}: {why}");
                return 1;
            }
            Anisofem.af_positions(m, state, x);
            double lowest = double.MaxValue;
            for (int i = 0; i < n; i++) lowest = Math.Min(lowest, x[3 * i + 2]);
            Console.WriteLine(lowest.ToString("R", CultureInfo.InvariantCulture));
        }
        Anisofem.af_free(m);
        return 0;
    }
}
